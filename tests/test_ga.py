"""The GA of method step 4 (vision/ga.py) and the heading/tilt parametrisation (geometry.py),
on toy fitness functions: fast, seeded."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoservo.vision.ga import GA, PAPER_BITS, GAParams, Region, paper_params
from photoservo.geometry import (
    heading_tilt_error,
    heading_tilt_from_rotation,
    rotation_from_heading_tilt,
    tilt_angle,
)

LO = np.array([0.0, 0.0, 0.3, -math.pi, -1.0, -1.0, -3.0])
HI = np.array([640.0, 480.0, 5.0, math.pi, 1.0, 1.0, 3.0])
PERIODIC = [False, False, False, True, False, False, False]
PEAK = np.array([300.0, 200.0, 2.0, 3.0, 0.3, -0.2, 0.5])

REAL = GAParams(coding="real", population=30, elite=2, tournament=3, crossover=0.7, mutation=0.4,
                sigma=0.1, sigma_min=0.002, local_share=0.3, bits=PAPER_BITS)


def peak_fitness(g: np.ndarray) -> np.ndarray:
    """A narrow 7-D Gaussian peak (3 % of each range) at PEAK; heading periodic."""
    d = (g - PEAK) / (HI - LO)
    d[:, 3] = (np.mod(g[:, 3] - PEAK[3] + math.pi, 2 * math.pi) - math.pi) / (2 * math.pi)
    return np.exp(-np.sum((d / 0.03) ** 2, axis=1))


def region() -> Region:
    return Region.box(LO, HI, PERIODIC)


def test_paper_chromosome_is_68_bits():
    assert sum(PAPER_BITS) == 68
    p = paper_params()
    assert (p.coding, p.population) == ("binary", 30)


def test_real_ga_converges_on_a_narrow_peak():
    found = 0
    for seed in range(5):
        ga = GA(peak_fitness, region(), REAL, np.random.default_rng(seed))
        _g, f = ga.step(300)
        found += f > 0.99
    assert found == 5


def test_binary_ga_climbs_from_random_start():
    ga = GA(peak_fitness, region(), paper_params(), np.random.default_rng(1))
    start = ga.best()[1]
    # a broad peak the 68-bit GA can find in a few hundred generations
    ga.set_fitness(lambda g: np.exp(-np.sum(((g - PEAK) / (HI - LO) / 0.2) ** 2, axis=1)))
    _g, f = ga.step(300)
    assert f > 0.9 and f > start


def test_binary_encode_decode_roundtrip_within_one_step():
    ga = GA(peak_fitness, region(), paper_params(), np.random.default_rng(0))
    g = region().sample(np.random.default_rng(5), 50)
    chrom = ga.encode(g)
    assert chrom.shape == (50, 68) and chrom.dtype == bool
    back = ga.decode(chrom)
    step = (HI - LO) / (2.0 ** np.array(PAPER_BITS) - 1)
    err = np.abs(back - g)
    err[:, 3] = np.abs(np.mod(back[:, 3] - g[:, 3] + math.pi, 2 * math.pi) - math.pi)
    assert np.all(err <= step * 0.5 + 1e-9)


@pytest.mark.parametrize("coding", ["real", "binary"])
def test_same_seed_same_run_and_step_is_resumable(coding):
    p = REAL if coding == "real" else paper_params()
    a = GA(peak_fitness, region(), p, np.random.default_rng(7))
    b = GA(peak_fitness, region(), p, np.random.default_rng(7))
    a.step(20)
    for _ in range(4):
        b.step(5)  # the population persists between calls
    assert np.array_equal(a.genes, b.genes)
    assert a.generation == b.generation == 20


def test_elitism_never_loses_the_best():
    ga = GA(peak_fitness, region(), REAL, np.random.default_rng(3))
    best = -np.inf
    for _ in range(50):
        _, f = ga.step(1)
        assert f >= best
        best = f


def test_inject_replaces_the_worst_and_keeps_the_best():
    ga = GA(peak_fitness, region(), REAL, np.random.default_rng(0))
    ga.step(3)
    g_best, _f_best = ga.best()
    ga.inject(np.repeat(PEAK[None], 5, axis=0))
    genes, scores = ga.ranked()
    assert scores[0] == pytest.approx(1.0)
    assert np.sum(np.all(np.isclose(genes, PEAK), axis=1)) == 5
    assert any(np.allclose(g, g_best) for g in genes)


def test_set_region_resamples_individuals_outside():
    ga = GA(peak_fitness, region(), REAL, np.random.default_rng(0))
    win = Region.box(PEAK - 0.05 * (HI - LO), PEAK + 0.05 * (HI - LO))
    ga.set_region(win)
    assert np.all(win.contains(ga.genes))
    _g, f = ga.step(30)
    assert f > 0.9


def test_params_validation_names_the_key():
    from photoservo.errors import InputError

    with pytest.raises(InputError, match="ga.elite"):
        dataclasses.replace(REAL, elite=30).validate("ga")
    with pytest.raises(InputError, match="ga.bits"):
        dataclasses.replace(REAL, bits=(10, 10)).validate("ga")


# ----------------------------------------------------------------------------- pose parametrisation

angles = st.floats(-math.pi, math.pi, allow_nan=False)
tilts = st.floats(-1.2, 1.2, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(angles, tilts, tilts)
def test_heading_tilt_roundtrip(psi, tx, ty):
    R = rotation_from_heading_tilt(psi, tx, ty)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
    # the tilt is the angle between the model normal and the optical axis
    assert tilt_angle(R) == pytest.approx(math.hypot(tx, ty), abs=1e-9)
    R2 = rotation_from_heading_tilt(*heading_tilt_from_rotation(R))
    assert np.allclose(R, R2, atol=1e-9)


def test_heading_and_tilt_errors_are_separate():
    R = rotation_from_heading_tilt(0.4, 0.2, -0.1)
    h, t = heading_tilt_error(R, rotation_from_heading_tilt(0.4 + math.radians(3), 0.2, -0.1))
    assert (h, t) == (pytest.approx(3.0), pytest.approx(0.0, abs=1e-6))
    # tipping the model about its own x axis changes the tilt only
    tip = rotation_from_heading_tilt(0.0, math.radians(4), 0.0)
    h, t = heading_tilt_error(R, R @ tip)
    assert h == pytest.approx(0.0, abs=1e-6) and t == pytest.approx(4.0)
