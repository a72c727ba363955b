"""Compile a C source to a shared library once, keep it on disk by the source's hash, load it.

A C compiler is the only thing this needs (``cc``, or ``$CC``); where there is none, or it
fails, ``load`` returns None and the caller integrates in Python, with one log line saying
why. Libraries are kept under ``$PIDYN_CACHE`` (default: ``~/.cache/pidyn/kernels``), written
under a temporary name and renamed, so that parallel test workers and runs share them safely.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import platform
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

log = logging.getLogger(__name__)

#: flags that keep the order of floating-point operations (no fused multiply-add, no fast math),
#: so that results agree with NumPy's to round-off
FLAGS = ["-O2", "-shared", "-fPIC", "-std=c99", "-ffp-contract=off", "-fno-fast-math"]
_LOADED: dict[str, ctypes.CDLL | None] = {}
_WARNED: set[str] = set()


def cache_dir() -> Path:
    root = os.environ.get("PIDYN_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "pidyn"
    )
    return Path(root) / "kernels"


def compiler() -> str | None:
    for name in (os.environ.get("CC"), sysconfig.get_config_var("CC"), "cc", "gcc", "clang"):
        exe = shutil.which(str(name).split()[0]) if name else None
        if exe:
            return exe
    return None


def _say_once(key: str, message: str) -> None:
    if key not in _WARNED:
        _WARNED.add(key)
        log.info("%s; simulating in Python (slower, same results)", message)


def load(source: str) -> ctypes.CDLL | None:
    """The library built from ``source`` (cached in memory and on disk), or None."""
    # a home folder shared by machines of other kinds keeps each kind's library apart
    where = f"{platform.machine()} {sys.implementation.cache_tag} {compiler()}"
    key = hashlib.sha256((source + where).encode()).hexdigest()[:24]
    if key in _LOADED:
        return _LOADED[key]
    lib = None
    try:
        path = cache_dir() / f"rk4_{key}.so"
        if not path.exists():
            _compile(source, path)
        lib = ctypes.CDLL(str(path)) if path.exists() else None
    except OSError as exc:  # an unwritable cache, a library that will not load
        _say_once("load", f"no compiled simulation ({exc})")
    _LOADED[key] = lib
    return lib


def _compile(source: str, path: Path) -> None:
    cc = compiler()
    if cc is None:
        _say_once("cc", "no C compiler found (set CC)")
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
        src, out = Path(tmp) / "kernel.c", Path(tmp) / "kernel.so"
        src.write_text(source)
        done = subprocess.run([cc, *FLAGS, "-o", str(out), str(src), "-lm"], capture_output=True, text=True)
        if done.returncode != 0:
            _say_once("compile", f"the C compiler failed: {done.stderr.strip()[:500]}")
            return
        os.replace(out, path)
