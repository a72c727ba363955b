"""A run's PNG figures go into TensorBoard as the files themselves."""

from __future__ import annotations

import numpy as np
import pytest
from tensorboard.backend.event_processing.event_accumulator import IMAGES, EventAccumulator
from torch.utils.tensorboard import SummaryWriter

from pidyn.reporting import pyplot
from pidyn.runs.tb_images import add_png, png_summary


def _png(path, size=(3.0, 2.0)):
    plt = pyplot()
    fig, ax = plt.subplots(figsize=size)
    ax.plot([0, 1], [0, 1])
    fig.savefig(path, dpi=50)
    plt.close(fig)
    return path


def test_the_file_goes_in_as_written(tmp_path):
    png = _png(tmp_path / "a.png")
    with SummaryWriter(str(tmp_path / "tb")) as writer:
        add_png(writer, "figures/a", png, 7)
    acc = EventAccumulator(str(tmp_path / "tb"), size_guidance={IMAGES: 0})
    acc.Reload()
    (event,) = acc.Images("figures/a")
    assert event.step == 7
    assert (event.width, event.height) == (150, 100)
    assert event.encoded_image_string == png.read_bytes()


def test_a_writer_without_a_file_writer_gets_the_pixels(tmp_path):
    png = _png(tmp_path / "b.png")
    got = {}

    class Plain:
        def add_image(self, tag, img, step):
            got.update(tag=tag, shape=img.shape, step=step, max=float(np.max(img)))

    add_png(Plain(), "figures/b", png, 3)
    assert got == {"tag": "figures/b", "shape": (3, 100, 150), "step": 3, "max": 1.0}


def test_a_file_that_is_no_png_is_refused():
    with pytest.raises(ValueError, match="figures/c: not a PNG"):
        png_summary("figures/c", b"GIF89a" + b"\0" * 40)
