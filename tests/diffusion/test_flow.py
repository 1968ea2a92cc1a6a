import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from symdrive_core.diffusion import flow
from symdrive_core.diffusion.sampler import SamplerConfig, restore_image

from .helpers import OracleRestorer, tiny_builtin


def test_timesteps_run_from_one_to_zero_and_shift_keeps_the_ends():
    for mu in (0.0, 1.15):
        ts = flow.timesteps(7, mu)
        assert len(ts) == 8 and ts[0] == 1.0 and ts[-1] == 0.0
        assert bool(torch.all(ts[1:] < ts[:-1]))
    assert bool(torch.all(flow.timesteps(7, 1.15)[1:-1] > flow.timesteps(7)[1:-1]))  # more time at high noise


@pytest.mark.parametrize("steps,n_start", [(1, 0), (4, 0), (50, 10), (50, 49)])
def test_euler_with_the_exact_velocity_lands_on_the_data(steps, n_start):
    g = torch.Generator().manual_seed(1)
    y = torch.rand(1, 3, 8, 12, generator=g)
    init = torch.rand(1, 3, 8, 12, generator=g)
    oracle = OracleRestorer(y)
    out = restore_image(oracle, init, init, init, SamplerConfig(steps=steps, n_start=n_start))
    assert torch.allclose(out, y, atol=1e-5)
    assert len(oracle.calls) == steps - n_start


def test_start_state_has_the_paper_statistics():
    ts = flow.timesteps(50)
    z_cond = torch.full((1, 1, 400, 400), 0.7)
    z = flow.start_state(z_cond, ts, 10, torch.Generator().manual_seed(0))
    sigma = float(ts[10])
    assert sigma == pytest.approx(0.8)
    assert float(z.mean()) == pytest.approx((1 - sigma) * 0.7, abs=0.01)
    assert float(z.std()) == pytest.approx(sigma, rel=0.02)
    assert torch.equal(
        flow.start_state(z_cond, ts, 0, torch.Generator().manual_seed(3)),
        torch.randn(z_cond.shape, generator=torch.Generator().manual_seed(3)),
    )
    with pytest.raises(ValueError, match="n_start"):
        flow.start_state(z_cond, ts, 50, torch.Generator())


@settings(max_examples=25, deadline=None)
@given(t=st.floats(0.0, 0.9), dt=st.floats(0.02, 1.0), x0=st.floats(-1.0, 1.0))
def test_renoise_keeps_the_flow_marginals(t, dt, x0):
    t_up = min(1.0, t + dt)
    g = torch.Generator().manual_seed(0)
    n = 200_000
    z_t = flow.noised(torch.full((n,), x0), torch.randn(n, generator=g), t)
    z_up = flow.renoise(z_t, t, t_up, g)
    assert float(z_up.mean()) == pytest.approx((1 - t_up) * x0, abs=0.01)
    assert float(z_up.std()) == pytest.approx(t_up, abs=0.01)


def test_renoise_rejects_going_down():
    with pytest.raises(ValueError):
        flow.renoise(torch.zeros(3), 0.5, 0.4, torch.Generator())


def test_sampling_is_seeded():
    model = tiny_builtin()
    g = torch.Generator().manual_seed(0)
    a, b = torch.rand(1, 3, 16, 16, generator=g), torch.rand(1, 3, 16, 16, generator=g)
    run = lambda seed: restore_image(model, a, b, a, SamplerConfig(steps=6, n_start=2, seed=seed))
    assert torch.equal(run(4), run(4))
    assert not torch.equal(run(4), run(5))


def test_flow_loss_is_zero_for_the_true_velocity_and_positive_otherwise():
    x0 = torch.rand(2, 3, 4, 4)

    def exact(z, t):  # v = eps - x0 recovered from z and the known x0
        tt = t.reshape(-1, 1, 1, 1)
        return (z - x0) / tt

    assert float(flow.flow_loss(exact, x0, torch.Generator().manual_seed(0))) < 1e-8
    assert float(flow.flow_loss(lambda z, t: torch.zeros_like(z), x0, torch.Generator().manual_seed(0))) > 0.1


def test_training_times_cover_the_sampled_range():
    g = torch.Generator().manual_seed(0)
    t = flow.training_times(4000, g, t_max=0.8, full_fraction=0.1)
    assert float(t.min()) >= 0.0 and float(t.max()) <= 1.0
    share_above = float((t > 0.8).float().mean())
    assert 0.005 < share_above < 0.04  # ~10% drawn on [0, 1], a fifth of them above 0.8
    assert float((flow.training_times(4000, g, t_max=0.8) > 0.8).float().sum()) == 0.0


def test_averaged_samples_land_on_the_data_with_the_exact_velocity():
    g = torch.Generator().manual_seed(2)
    y, init = torch.rand(1, 3, 8, 12, generator=g), torch.rand(1, 3, 8, 12, generator=g)
    out = restore_image(OracleRestorer(y), init, init, init, SamplerConfig(steps=5, n_start=4, samples=6))
    assert out.shape == y.shape and torch.allclose(out, y, atol=1e-5)


def test_averaging_k_samples_divides_the_seed_variance_by_about_k():
    """The mean of K samples estimates the posterior mean: its spread over seeds shrinks like 1/K."""
    model = tiny_builtin(seed=1)
    g = torch.Generator().manual_seed(0)
    a, b = torch.rand(1, 3, 16, 16, generator=g), torch.rand(1, 3, 16, 16, generator=g)

    def spread(samples: int) -> float:
        outs = torch.cat([restore_image(model, a, b, a, SamplerConfig(steps=5, n_start=2, seed=s, samples=samples))
                          for s in range(12)])
        return float(outs.var(dim=0).mean())

    ratio = spread(1) / spread(8)
    assert 4.0 < ratio < 16.0


def test_a_noise_free_start_is_one_deterministic_evaluation():
    """No noise is drawn: the seed and ``samples`` change nothing, the restorer runs once on a
    batch of one, and with the exact velocity one step still lands on the data."""
    g = torch.Generator().manual_seed(3)
    y, init = torch.rand(1, 3, 8, 12, generator=g), torch.rand(1, 3, 8, 12, generator=g)
    oracle = OracleRestorer(y)
    out = restore_image(oracle, init, init, init, SamplerConfig(steps=5, n_start=4, samples=8, noise_free=True))
    assert torch.allclose(out, y, atol=1e-5)
    assert len(oracle.calls) == 1 and oracle.calls[0][0].shape[0] == 1
    model = tiny_builtin(seed=2)
    a, b = torch.rand(1, 3, 16, 16, generator=g), torch.rand(1, 3, 16, 16, generator=g)
    run = lambda seed, samples: restore_image(model, a, b, a, SamplerConfig(steps=5, n_start=4, seed=seed,
                                                                            samples=samples, noise_free=True))
    assert torch.equal(run(0, 1), run(7, 8))
    # the state it starts from is the noisy one's mean: (1 - t) init
    z = 0.8 * (a * 2 - 1)
    v = model.velocity(z, torch.full((1,), 0.2), a * 2 - 1, b * 2 - 1)
    assert torch.allclose(run(0, 1), ((z - 0.2 * v) * 0.5 + 0.5).clamp(0, 1), atol=1e-6)
    # from pure noise there is no initialisation to start from: the noise is drawn as asked
    from_noise = lambda seed: restore_image(model, a, b, None, SamplerConfig(steps=2, n_start=0, seed=seed,
                                                                             noise_free=True))
    assert torch.equal(from_noise(1), from_noise(1)) and not torch.equal(from_noise(1), from_noise(2))


def test_a_step_from_a_degraded_start_lands_on_the_data():
    g = torch.Generator().manual_seed(3)
    x0, start, eps = (torch.rand(2, 3, 5, 6, generator=g) for _ in range(3))
    t = torch.tensor([0.2, 0.7])
    z = flow.noised(start, eps, t)
    v = flow.start_velocity_target(x0, start, eps, t)
    assert torch.allclose(z - t.reshape(-1, 1, 1, 1) * v, x0, atol=1e-6)
    # from the data itself it is the plain flow target, even at t = 0
    zero = torch.tensor([0.0, 0.5])
    assert torch.equal(flow.start_velocity_target(x0, x0, eps, zero), flow.velocity_target(x0, eps))


def test_flow_loss_from_degraded_starts_keeps_them_away_from_t_zero():
    g = torch.Generator().manual_seed(4)
    x0 = torch.rand(64, 3, 4, 4, generator=g)
    start = x0.clone()
    start[:32] = torch.rand(32, 3, 4, 4, generator=g)  # the first half starts degraded
    seen = {}

    def exact(z, t):  # the velocity that leads each state to x0
        seen["t"] = t
        return (z - x0) / t.reshape(-1, 1, 1, 1)

    loss = flow.flow_loss(exact, x0, torch.Generator().manual_seed(0), t_max=0.85, x_start=start, start_t_min=0.1)
    assert float(loss) < 1e-8
    t = seen["t"]
    assert float(t[:32].min()) >= 0.1 and float(t[32:].min()) < 0.1
    assert float(t.max()) <= 0.1 + 0.9 * 0.85 + 1e-6
