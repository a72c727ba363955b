"""Seeded buildings as the building studies draw them: storeys, masses, stiffnesses and dashpots,
and which floors carry a sensor."""

from __future__ import annotations

import numpy as np


def draw_building(rng: np.random.Generator) -> tuple[int, list[float], list[float], list[float]]:
    """Storeys (3-5), masses (0.8-1.2), stiffnesses (150-250 N/m at the ground, half that at the
    top) and dashpots (2 % of critical per storey) of a seeded building."""
    n = int(rng.integers(3, 6))
    masses = [round(float(m), 3) for m in rng.uniform(0.8, 1.2, n)]
    k0 = float(rng.uniform(150.0, 250.0))
    stiff = [round(k0 * (1 - 0.5 * j / max(n - 1, 1)), 2) for j in range(n)]
    damp = [round(0.02 * 2 * np.sqrt(k * m), 4) for k, m in zip(stiff, masses)]
    return n, masses, stiff, damp


def draw_sensors(rng: np.random.Generator, n: int) -> list[int]:
    """Every floor, or, one building in three, every floor but one between the first and the top."""
    sensors = list(range(1, n + 1))
    if rng.random() < 1 / 3:
        sensors.remove(int(rng.integers(2, n)))
    return sensors
