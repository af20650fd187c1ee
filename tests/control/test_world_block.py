"""The closed-form sample block of the linear world model equals the per-sample recursion it replaces."""

from __future__ import annotations

import numpy as np
import pytest

from tubempc.control.disturbance import make_disturbance
from tubempc.control.reference_loop import _world_block


@pytest.mark.parametrize("kind", ["random", "worst", "sine", "bias"])
def test_block_matches_per_sample_recursion(kind: str) -> None:
    m, dt, sigma, bound = 10, 0.01, 2.0, 0.02
    a = 1.0 - sigma * dt
    powers = a ** np.arange(m + 1)
    lower = np.array([[a ** (k - 1 - j) if j < k else 0.0 for j in range(m)] for k in range(m + 1)])
    x = np.array([0.1, -0.2, 0.01])
    x_hat = np.array([0.105, -0.2, 0.0])
    u_hat = np.array([0.18, 0.0, 0.0])
    t_arr = np.arange(m) * dt + 3.0
    noise_m = 0.0 if kind == "worst" else 0.001
    arrays = {name: np.zeros((m, 3)) for name in ("xs", "xms", "xhs", "uw")}
    dist = make_disturbance(kind, bound, np.random.default_rng(5))
    x_end, xh_end = _world_block(0, m, x, x_hat, u_hat, t_arr=t_arr, dist=dist, rng=np.random.default_rng(6),
                                 sigma=sigma, dt=dt, noise_m=noise_m, powers=powers, lower=lower, **arrays)
    # replay: the same random draws, in the same order, through the per-sample law
    dist2 = make_disturbance(kind, bound, np.random.default_rng(5))
    rng2 = np.random.default_rng(6)
    noise = np.zeros((m, 3))
    if noise_m > 0:
        noise[:, :2] = rng2.normal(scale=noise_m, size=(m, 2))
    deltas = None if kind == "worst" else dist2.batch(t_arr)
    xr, xhr = x.copy(), x_hat.copy()
    for k in range(m):
        u = u_hat - sigma * (xr + noise[k] - xhr)
        # rounding only: the closed form sums the same terms in another order (1e-15 m on 1 m values)
        assert arrays["xs"][k] == pytest.approx(xr, abs=1e-14)
        assert arrays["uw"][k] == pytest.approx(u, abs=1e-13)
        delta = dist2.sample(0.0, xr - xhr) if deltas is None else deltas[k]
        xr = xr + dt * (u + delta)
        xhr = xhr + dt * u_hat
    assert x_end == pytest.approx(xr, abs=1e-14)
    assert xh_end == pytest.approx(xhr, abs=1e-14)


@pytest.mark.parametrize("kind", ["random", "worst", "sine"])
def test_casadi_block_matches_the_closed_form_on_the_world_model(kind: str) -> None:
    from tubempc.control import world_model
    from tubempc.control.closed_loop import _block_function
    from tubempc.control.reference_loop import _casadi_block

    m, dt, sigma, bound = 10, 0.01, 2.0, 0.02
    a = 1.0 - sigma * dt
    powers = a ** np.arange(m + 1)
    lower = np.array([[a ** (k - 1 - j) if j < k else 0.0 for j in range(m)] for k in range(m + 1)])
    x = np.array([0.1, -0.2, 0.01])
    x_hat = np.array([0.105, -0.2, 0.0])
    u_hat = np.array([0.1, -0.12, 0.02])
    noise_m = 0.0 if kind == "worst" else 0.001
    t_arr = 2.0 + dt * np.arange(m)
    closed = {name: np.zeros((m, 3)) for name in ("xs", "xms", "xhs", "uw")}
    end_a = _world_block(0, m, x, x_hat, u_hat, t_arr=t_arr, dist=make_disturbance(kind, bound,
                         np.random.default_rng(1)), rng=np.random.default_rng(2), sigma=sigma, dt=dt,
                         noise_m=noise_m, powers=powers, lower=lower, **closed)
    rk4 = {name: np.zeros((m, 3)) for name in ("xs", "xms", "xhs", "uw")}
    end_b = _casadi_block(0, m, x, x_hat, u_hat, t0_s=2.0, dist=make_disturbance(kind, bound,
                          np.random.default_rng(1)), rng=np.random.default_rng(2), sigma=sigma, dt=dt,
                          noise_m=noise_m, fn=_block_function(world_model(), dt, m), samples=m, **rk4)
    # RK4 is exact for the world model's constant-rate motion over a sample: equal up to rounding
    for name, values in closed.items():
        assert np.allclose(values, rk4[name], rtol=0, atol=1e-13), name
    assert np.allclose(end_a[0], end_b[0], rtol=0, atol=1e-13)
    assert np.allclose(end_a[1], end_b[1], rtol=0, atol=1e-13)


@pytest.mark.parametrize(("kind", "m_blk"), [("worst", 10), ("worst", 1), ("random", 10), ("random", 3)])
def test_per_run_constants_give_the_same_block(kind: str, m_blk: int) -> None:
    m, dt, sigma, bound = 10, 0.01, 2.0, 0.02
    a = 1.0 - sigma * dt
    powers = a ** np.arange(m + 1)
    lower = np.array([[a ** (k - 1 - j) if j < k else 0.0 for j in range(m)] for k in range(m + 1)])
    x, x_hat, u_hat = np.array([0.1, -0.2, 0.01]), np.array([0.105, -0.2, 0.0]), np.array([0.18, 0.0, 0.0])
    t_arr = np.arange(m) * dt + 3.0
    outs = []
    for consts in ({}, {"k_dt": (np.arange(m + 1) * dt)[:, None],
                        "drift": dt * bound * (1.0 - powers) / (sigma * dt)}):
        arrays = {name: np.zeros((m, 3)) for name in ("xs", "xms", "xhs", "uw")}
        dist = make_disturbance(kind, bound, np.random.default_rng(5))
        ends = _world_block(0, m_blk, x, x_hat, u_hat, t_arr=t_arr, dist=dist, rng=np.random.default_rng(6),
                            sigma=sigma, dt=dt, noise_m=0.0, powers=powers, lower=lower, **consts, **arrays)
        outs.append((*ends, *arrays.values()))
    # exact: the constants are the same expressions, evaluated once per run instead of once per block
    assert all(np.array_equal(p, q) for p, q in zip(*outs, strict=True))
