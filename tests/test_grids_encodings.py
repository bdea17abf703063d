"""SphericalHarmonics, FrequencyEncoding, LevelSchedule and the public names of grids."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.special import sph_harm_y
from torch.autograd import gradgradcheck

import hybridneus.grids as grids
from hybridneus.errors import ConfigError
from hybridneus.grids import FrequencyEncoding, LevelSchedule, SphericalHarmonics


def test_every_public_name_resolves():
    for name in grids.__all__:
        assert getattr(grids, name) is not None, name
    ns: dict = {}
    exec("from hybridneus.grids import *", ns)
    assert set(grids.__all__) <= set(ns)


def _real_sh_scipy(dirs: np.ndarray, degree: int) -> np.ndarray:
    """Real SH from scipy's complex Y_l^m (Condon-Shortley phase), tcnn's sign convention."""
    theta = np.arccos(np.clip(dirs[:, 2], -1, 1))
    phi = np.arctan2(dirs[:, 1], dirs[:, 0])
    cols = []
    for ell in range(degree):
        for m in range(-ell, ell + 1):
            y = sph_harm_y(ell, abs(m), theta, phi)
            if m < 0:
                cols.append(math.sqrt(2) * y.imag)
            elif m == 0:
                cols.append(y.real)
            else:
                cols.append(math.sqrt(2) * y.real)
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("degree", [1, 2, 3, 4])
def test_sh_matches_scipy(degree):
    rng = np.random.default_rng(0)
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    out = SphericalHarmonics(degree)(torch.from_numpy(d))
    assert out.shape == (50, degree**2) and out.dtype == torch.float64
    np.testing.assert_allclose(out.numpy(), _real_sh_scipy(d, degree), atol=1e-12)


def test_sh_known_values_and_batch_shape():
    sh = SphericalHarmonics(2)
    c1 = math.sqrt(3 / (4 * math.pi))
    out = sh(torch.tensor([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    c0 = 0.5 / math.sqrt(math.pi)
    expect = torch.tensor([[c0, 0, 0, -c1], [c0, -c1, 0, 0], [c0, 0, c1, 0]])
    torch.testing.assert_close(out, expect)
    assert SphericalHarmonics(4)(torch.rand(2, 3, 5, 3)).shape == (2, 3, 5, 16)


def test_sh_twice_differentiable_and_errors():
    d = torch.nn.functional.normalize(torch.randn(4, 3, dtype=torch.float64), dim=-1)
    assert gradgradcheck(SphericalHarmonics(4), (d.requires_grad_(True),))
    with pytest.raises(ConfigError, match="degree"):
        SphericalHarmonics(5)
    with pytest.raises(ValueError, match="dirs"):
        SphericalHarmonics(2)(torch.rand(3, 2))


def test_frequency_layout_without_annealing():
    enc = FrequencyEncoding(3, n_anneal=None)
    assert enc.out_dim == 3 * (1 + 2 * 3)
    x = torch.rand(5, 3, dtype=torch.float64)
    out = enc(x)
    expect = [x]
    for k in range(3):
        expect += [torch.sin(2**k * x), torch.cos(2**k * x)]
    torch.testing.assert_close(out, torch.cat(expect, dim=-1))
    enc2 = FrequencyEncoding(2, include_input=False, n_anneal=0, in_dim=2)
    assert enc2.out_dim == 8 and enc2(torch.rand(4, 7, 2)).shape == (4, 7, 8)


def test_frequency_annealing_formula():
    n, n_fmin, n_fmax, n_anneal = 6, 1, 5, 1000
    enc = FrequencyEncoding(n, n_fmin=n_fmin, n_fmax=n_fmax, n_anneal=n_anneal)
    x = torch.rand(3, 3, dtype=torch.float64)
    for step in [0, 100, 250, 499, 1000, 5000]:
        enc.update_step(step)
        alpha = (n_fmax - n_fmin) * step / n_anneal
        beta = [
            (1 - math.cos(math.pi * min(max(alpha - k + n_fmin, 0.0), 1.0))) / 2 for k in range(n)
        ]
        torch.testing.assert_close(enc.band_weights(), torch.tensor(beta, dtype=torch.float64))
        assert enc.full_bands() == sum(b >= 1.0 for b in beta)
        out = enc(x)
        for k in range(n):
            blk = out[:, 3 + 6 * k : 3 + 6 * k + 6]
            exp = beta[k] * torch.cat([torch.sin(2**k * x), torch.cos(2**k * x)], dim=-1)
            torch.testing.assert_close(blk, exp)
    enc.update_step(0)
    assert enc.band_weights()[0] == 1.0 and enc.band_weights()[1] == 0.0


def test_frequency_step_survives_state_dict_and_errors():
    a = FrequencyEncoding(4)
    a.update_step(12345)
    b = FrequencyEncoding(4)
    b.load_state_dict(a.state_dict())
    torch.testing.assert_close(a.band_weights(), b.band_weights())
    assert b.full_bands() == a.full_bands() == 1  # the host copy of the step is restored too
    with pytest.raises(ConfigError, match="n_fmin"):
        FrequencyEncoding(4, n_fmin=5)
    with pytest.raises(ValueError, match="in_dim|shape"):
        FrequencyEncoding(4)(torch.rand(2, 4))


def test_level_schedule():
    s = LevelSchedule(4, 1000)
    assert [s.levels_at(t) for t in (0, 999, 1000, 2500, 12000)] == [4, 4, 5, 6, 16]
    assert LevelSchedule(2, 10, 2, max_levels=8).levels_at(1000) == 8
    with pytest.raises(ConfigError):
        LevelSchedule(0, 10)
