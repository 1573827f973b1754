"""Reward functions against hand computations of their thesis equations (numpy, float64)."""

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from temporal_torchrl.rewards import (
    DIRECTIONAL,
    IMAGE_INPUTS,
    OBJECTIVES,
    POSITIONAL,
    REWARDS,
    RewardHeads,
    SequenceEncoder,
    TemporalReward,
    cosine_similarity,
    direction_certainty,
    heads_input_dims,
    objective_of,
    reference_scales,
    register_reward,
    straight_window,
    unregister_reward,
    window_tokens,
)

D, HIDDEN, OUT, BATCH, ALPHA = 5, 7, 3, 4, 0.4
WINDOW = 4  # K of the window rewards (d_sequence) in these tests


def make_heads(variant, seed=0):
    torch.manual_seed(seed)
    image_dim, text_dim = heads_input_dims(variant, D)
    sequence_length = WINDOW - 1 if IMAGE_INPUTS[variant] == "window" else None
    return RewardHeads(image_dim, text_dim, hidden_dim=HIDDEN, out_dim=OUT,
                       sequence_length=sequence_length)


def path(s, s_prev):
    """A curved window of WINDOW embeddings from s_prev to s (steps in different directions)."""
    fractions = torch.linspace(0, 1, WINDOW, dtype=s.dtype).unsqueeze(-1)
    bend = torch.sin(torch.pi * fractions) * (s - s_prev).roll(1, dims=-1).unsqueeze(-2)
    window = s_prev.unsqueeze(-2) + fractions * (s - s_prev).unsqueeze(-2) + bend
    window[..., -1, :] = s  # exactly s_t at the newest slot
    return window


def mlp(head, x):
    """f(x) = W2 relu(W1 x + b1) + b2 with the head's weights, one vector at a time."""
    w1, b1 = head[0].weight.detach().double().numpy(), head[0].bias.detach().double().numpy()
    w2, b2 = head[2].weight.detach().double().numpy(), head[2].bias.detach().double().numpy()
    return w2 @ np.maximum(w1 @ x + b1, 0.0) + b2


def csim(x, y):
    return float(x @ y / (np.linalg.norm(x) * np.linalg.norm(y)))


def unit(x):
    return x / np.linalg.norm(x)


def regularise(x, g, b, alpha, projection):
    """Eq. 4.5's alpha proj_L x + (1 - alpha) x.

    ``origin`` (thesis, and its release's ``gb_reward_before``): x projected onto the direction
    g - b through the origin, on the vectors as given. ``line`` (VLM-RMs): unit x, g, b, and the
    projection onto the line through b and g.
    """
    if projection == "line":
        x, g, b = unit(x), unit(g), unit(b)
        d = g - b
        proj = b + ((x - b) @ d) / (d @ d) * d
    else:
        d = g - b
        proj = (x @ d) / (d @ d) * d
    return alpha * proj + (1 - alpha) * x


def reference(variant, heads, s, s0, s_prev, g, b, alpha, projection="origin", position=None):
    """The thesis equation of ``variant`` for one row."""
    fi = (lambda x: mlp(heads.image, x)) if heads is not None else None
    fl = (lambda x: mlp(heads.text, x)) if heads is not None else None
    p = s if position is None else position
    if variant == "liv":
        return csim(s, g)
    if variant == "furl":
        return csim(fi(s), fl(g))
    if variant == "p1":
        return csim(fi(s - s0), fl(g - b))
    if variant == "p2":
        return csim(fi(s) - fi(s0), fl(g) - fl(b))
    if variant == "p3":
        u, vg, vb = unit(fi(s)), unit(fl(g)), unit(fl(b))
        return 1 - 0.5 * np.sum((regularise(u, vg, vb, alpha, projection) - vg) ** 2)
    if variant == "p4":
        x = regularise(s, g, b, alpha, projection)
        return 1 - 0.5 * np.sum((unit(fi(x)) - unit(fl(g))) ** 2)
    if variant == "d1":
        return csim(fi(unit(s - s_prev)), fl(g - b))
    if variant == "d2":
        return csim(fi(s) - fi(s_prev), fl(g) - fl(b))
    if variant == "d_sequence":
        # x_j = n(s_t) ⊕ n(w_j - w_{j-1}) into the sequence encoder (run by torch; the
        # equation around it is what is checked here).
        window = path(torch.from_numpy(s), torch.from_numpy(s_prev)).numpy()
        tokens = np.stack([np.concatenate([unit(p), unit(window[j] - window[j - 1])])
                           for j in range(1, WINDOW)])
        image = heads.image(torch.from_numpy(tokens).float()).detach().double().numpy()
        return csim(image, fl(g - b))
    if variant == "d_certainty":  # D3's equation; its heads are trained another way
        variant = "d3"
    position_part = {"d3": p, "d4": p - s0,
                     "d5": regularise(p, g, b, alpha, projection)}[variant]
    return csim(fi(np.concatenate([unit(position_part), unit(s - s_prev)])), fl(g - b))


@pytest.fixture
def embeddings():
    # Far from unit length (LIV embeddings are not normalised): a form that normalises s_t, g or
    # b where the equation does not gives other values.
    gen = torch.Generator().manual_seed(1)
    s, s0, s_prev, position = (3.0 * torch.randn(BATCH, D, generator=gen) for _ in range(4))
    g, b = 4.0 * torch.randn(D, generator=gen), 0.5 * torch.randn(D, generator=gen)
    return s, s0, s_prev, position, g, b


def _call(variant, heads, s, s0, s_prev, g, b, **kwargs):
    fn = {**POSITIONAL, **DIRECTIONAL}[variant]
    window = None if s_prev is None else path(s, s_prev)
    return fn(heads, s, s0=s0, s_prev=s_prev, g=g, b=b, alpha=ALPHA, window=window, **kwargs)


ALL_VARIANTS = [*POSITIONAL, *DIRECTIONAL]


@pytest.mark.parametrize("projection", ["origin", "line"])
@pytest.mark.parametrize("variant", ALL_VARIANTS)
def test_matches_hand_computation(variant, projection, embeddings):
    s, s0, s_prev, _, g, b = embeddings
    heads = None if variant == "liv" else make_heads(variant)
    got = _call(variant, heads, s, s0, s_prev, g, b, projection=projection)
    assert got.shape == (BATCH,)
    n = lambda t: t.double().numpy()  # noqa: E731
    expected = [reference(variant, heads, n(s[i]), n(s0[i]), n(s_prev[i]), n(g), n(b), ALPHA,
                          projection) for i in range(BATCH)]
    np.testing.assert_allclose(got.detach().numpy(), expected, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("variant", ["d3", "d4", "d5"])
def test_position_keyword_scores_a_direction_at_a_fixed_position(variant, embeddings):
    s, s0, s_prev, position, g, b = embeddings
    heads = make_heads(variant)
    got = _call(variant, heads, s, s0, s_prev, g, b, position=position)
    n = lambda t: t.double().numpy()  # noqa: E731
    expected = [reference(variant, heads, n(s[i]), n(s0[i]), n(s_prev[i]), n(g), n(b), ALPHA,
                          position=n(position[i])) for i in range(BATCH)]
    np.testing.assert_allclose(got.detach().numpy(), expected, rtol=1e-5, atol=1e-6)
    # A single position vector broadcasts over a batch of directions.
    single = _call(variant, heads, s, s0, s_prev, g, b, position=position[0])
    assert single.shape == (BATCH,)
    torch.testing.assert_close(single[0], got[0])


def test_line_projection_equals_vlm_rms_quadratic_form(embeddings):
    """VLM-RMs: r = 1 - 1/2 ||(x - g) P||^2, P = alpha d d^T/||d||^2 + (1 - alpha) I."""
    s, _, _, _, g, b = embeddings
    heads = make_heads("p3")
    got = _call("p3", heads, s, None, None, g, b, projection="line")
    vg = unit(mlp(heads.text, g.double().numpy()))
    vb = unit(mlp(heads.text, b.double().numpy()))
    d = (vg - vb)[:, None]
    proj = ALPHA * (d @ d.T) / (d.T @ d) + (1 - ALPHA) * np.eye(OUT)
    for i in range(BATCH):
        u = unit(mlp(heads.image, s[i].double().numpy()))
        expected = 1 - 0.5 * np.sum(((u - vg) @ proj) ** 2)
        assert got[i].item() == pytest.approx(expected, rel=1e-5, abs=1e-6)


def test_identity_heads_turn_furl_into_zero_shot_csim():
    heads = RewardHeads(3, 3, hidden_dim=3, out_dim=3)
    with torch.no_grad():
        for head in (heads.image, heads.text):
            head[0].weight.copy_(torch.eye(3)), head[2].weight.copy_(torch.eye(3))
            head[0].bias.zero_(), head[2].bias.zero_()
    s, g = torch.tensor([[1.0, 2.0, 0.5], [3.0, 0.1, 1.0]]), torch.tensor([2.0, 1.0, 1.0])
    torch.testing.assert_close(POSITIONAL["furl"](heads, s, g=g), POSITIONAL["liv"](None, s, g=g))
    # Hand value: (1*2 + 2*1 + 0.5*1) / (sqrt(5.25) sqrt(6)).
    assert POSITIONAL["liv"](None, s, g=g)[0].item() == pytest.approx(4.5 / (5.25 * 6) ** 0.5)


def test_alpha_zero_reduces_p3_to_furl_and_p4_to_csim(embeddings):
    s, _, _, _, g, b = embeddings
    heads = make_heads("p3")
    p3 = POSITIONAL["p3"](heads, s, g=g, b=b, alpha=0.0)
    torch.testing.assert_close(p3, POSITIONAL["furl"](heads, s, g=g))
    p4 = POSITIONAL["p4"](heads, s, g=g, b=b, alpha=0.0)
    torch.testing.assert_close(p4, POSITIONAL["furl"](heads, s, g=g))


def test_p4_and_d5_regularise_the_raw_embedding_by_hand():
    """s = (2, 1, 1), g = (2, 2, 0), b = (1, -1, 0): d = g - b = (1, 3, 0), s·d / d·d = 1/2, so
    proj_L s = (0.5, 1.5, 0) and with alpha = 0.4 eq. 4.5 gives 0.4 proj_L s + 0.6 s =
    (1.4, 1.2, 0.6). Unit-normalising s, g, b first would give another direction
    (n(g) - n(b) is not parallel to g - b)."""
    s, s_prev = torch.tensor([[2.0, 1.0, 1.0]]), torch.tensor([[1.0, 0.0, 1.0]])
    g, b = torch.tensor([2.0, 2.0, 0.0]), torch.tensor([1.0, -1.0, 0.0])
    regularised = torch.tensor([[1.4, 1.2, 0.6]])
    torch.manual_seed(0)
    heads = RewardHeads(3, 3, hidden_dim=4, out_dim=2)
    got = POSITIONAL["p4"](heads, s, g=g, b=b, alpha=0.4)
    torch.testing.assert_close(got, POSITIONAL["furl"](heads, regularised, g=g))
    d_heads = RewardHeads(6, 3, hidden_dim=4, out_dim=2)
    got = DIRECTIONAL["d5"](d_heads, s, s_prev=s_prev, g=g, b=b, alpha=0.4)
    torch.testing.assert_close(got, DIRECTIONAL["d3"](d_heads, s, s_prev=s_prev, g=g, b=b,
                                                      position=regularised))


@pytest.mark.parametrize("variant", ["d1", "d3", "d4", "d5"])
def test_direction_magnitude_does_not_matter(variant, embeddings):
    # float64: s - (s - 1e-3 Δ) loses digits of Δ in float32.
    s, s0, s_prev, _, g, b = (t.double() for t in embeddings)
    heads = make_heads(variant).double()
    base = _call(variant, heads, s, s0, s_prev, g, b)
    for scale in (1e-3, 7.0):
        # Same position s, direction (s - s_prev) scaled: s - s_prev' = scale (s - s_prev).
        scaled_prev = s - scale * (s - s_prev)
        torch.testing.assert_close(_call(variant, heads, s, s0, scaled_prev, g, b,
                                         position=s), base)
    flipped = _call(variant, heads, s, s0, s + (s - s_prev), g, b, position=s)
    assert not torch.allclose(flipped, base), "the opposite direction should score differently"


def test_d3_position_magnitude_does_not_matter(embeddings):
    s, s0, s_prev, position, g, b = embeddings
    heads = make_heads("d3")
    base = _call("d3", heads, s, s0, s_prev, g, b, position=position)
    torch.testing.assert_close(_call("d3", heads, s, s0, s_prev, g, b, position=3 * position),
                               base)


@pytest.mark.parametrize("variant", ALL_VARIANTS)
def test_zero_direction_and_t0_give_finite_rewards(variant, embeddings):
    s, _, _, _, g, b = embeddings
    heads = None if variant == "liv" else make_heads(variant)
    # Episode start: s_t = s_0 = s_{t-k}.
    reward = _call(variant, heads, s, s, s, g, b)
    assert torch.isfinite(reward).all()
    if variant in ("d2", "p2"):
        assert torch.equal(reward, torch.zeros(BATCH))


@pytest.mark.parametrize("variant", [v for v in ALL_VARIANTS if v != "liv"])
def test_gradients_reach_both_heads_and_shapes_follow_the_batch(variant):
    heads = make_heads(variant)
    s, s0, s_prev = (torch.randn(2, 3, D) for _ in range(3))
    reward = _call(variant, heads, s, s0, s_prev, torch.randn(D), torch.randn(D))
    assert reward.shape == (2, 3)
    reward.sum().backward()
    assert next(heads.image.parameters()).grad.abs().sum() > 0
    assert heads.text[0].weight.grad.abs().sum() > 0


def test_missing_argument_is_named():
    with pytest.raises(ValueError, match="needs s0"):
        POSITIONAL["p1"](make_heads("p1"), torch.randn(D), g=torch.randn(D), b=torch.randn(D))
    with pytest.raises(ValueError, match="projection='middle'"):
        POSITIONAL["p4"](make_heads("p4"), torch.randn(D), g=torch.randn(D), b=torch.randn(D),
                         projection="middle")


def test_heads_input_dims():
    assert heads_input_dims("furl", 1024) == (1024, 1024)
    assert heads_input_dims("d1", 1024) == (1024, 1024)
    for variant in ("d3", "d4", "d5", "d_certainty", "d_sequence"):
        assert heads_input_dims(variant, 1024) == (2048, 1024)
    with pytest.raises(ValueError, match="zero-shot"):
        heads_input_dims("liv", 8)
    with pytest.raises(ValueError, match="'d9'.*furl"):
        heads_input_dims("d9", 8)
    heads = RewardHeads(*heads_input_dims("d3", 8))
    assert heads.image[0].in_features == 16 and heads.image[2].out_features == 64
    assert heads.text[0].out_features == 256


# --- TemporalReward -----------------------------------------------------------------------------

def _temporal(**kwargs):
    gen = torch.Generator().manual_seed(3)
    return TemporalReward(D, torch.randn(D, generator=gen), torch.randn(D, generator=gen),
                          **kwargs)


def test_combined_reward_is_task_plus_rho_times_vlm(embeddings):
    s, s0, s_prev, _, _, _ = embeddings
    reward = _temporal(positional="p2", directional="d4", rho=0.5, lambda_=4.0, alpha=0.3)
    success = torch.tensor([[True], [False], [False], [True]])
    out = reward(s, s0, s_prev, success)
    g, b = reward.goal_embedding, reward.baseline_embedding
    r_p = POSITIONAL["p2"](reward.positional_heads, s, s0=s0, g=g, b=b)
    r_d = DIRECTIONAL["d4"](reward.directional_heads, s, s0=s0, s_prev=s_prev, g=g, b=b)
    assert out["task_reward"].squeeze(-1).tolist() == [0.0, -1.0, -1.0, 0.0]
    torch.testing.assert_close(out["positional_reward"].squeeze(-1), r_p)
    torch.testing.assert_close(out["directional_reward"].squeeze(-1), r_d)
    torch.testing.assert_close(out["vlm_reward"].squeeze(-1), r_p + 4.0 * r_d)
    torch.testing.assert_close(out["reward"].squeeze(-1),
                               success.squeeze(-1).float() - 1 + 0.5 * (r_p + 4.0 * r_d))
    assert all(v.shape == (BATCH, 1) and v.dtype == torch.float32 for v in out.values())


@pytest.mark.parametrize("positional", ["p3", "p4"])
def test_alpha_from_the_config_reaches_p3_p4_and_d5(tmp_path, positional):
    """reward.alpha of a composed recipe config, through the recipe's own builder
    (factories.make_reward): at two values of alpha, P3 or P4 and D5 inside the combined reward
    each equal their thesis equation at that alpha (eq. 4.5 in 4.2.2 and 4.3.2, in numpy), and
    the two alphas give different rewards (a builder that dropped alpha gives both the
    default's)."""
    from helpers import config

    from temporal_torchrl.configs.rules import Devices
    from temporal_torchrl.training import factories

    gen = torch.Generator().manual_seed(4)
    s, s0, s_prev = (3.0 * torch.randn(BATCH, 16, generator=gen) for _ in range(3))
    success = torch.tensor([[False], [True], [False], [False]])
    parts = {}
    for alpha in (0.15, 0.85):
        cfg = config(tmp_path, f"reward.positional={positional}", "reward.directional=d5",
                     f"reward.alpha={alpha}", "reward.rho=0.5", "reward.lambda_=2.0")
        torch.manual_seed(0)  # the same heads at both alphas
        devices = Devices.of(cfg)
        reward = factories.make_reward(cfg, factories.make_encoder(cfg, devices.encoder), devices)
        with torch.no_grad():
            out = reward(s, s0, s_prev, success)
        g, b = (x.double().numpy() for x in (reward.goal_embedding, reward.baseline_embedding))
        rows = [(s[i].double().numpy(), s0[i].double().numpy(), s_prev[i].double().numpy())
                for i in range(BATCH)]
        expected_p = [reference(positional, reward.positional_heads, *row, g, b, alpha)
                      for row in rows]
        expected_d = [reference("d5", reward.directional_heads, *row, g, b, alpha)
                      for row in rows]
        np.testing.assert_allclose(out["positional_reward"].squeeze(-1).numpy(), expected_p,
                                   rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(out["directional_reward"].squeeze(-1).numpy(), expected_d,
                                   rtol=1e-5, atol=1e-6)
        expected = success.squeeze(-1).double().numpy() - 1 + 0.5 * (
            np.array(expected_p) + 2.0 * np.array(expected_d))
        np.testing.assert_allclose(out["reward"].squeeze(-1).numpy(), expected, rtol=1e-5,
                                   atol=1e-6)
        parts[alpha] = (np.array(expected_p), np.array(expected_d))
    (p_low, d_low), (p_high, d_high) = parts.values()
    assert np.abs(p_low - p_high).min() > 1e-4 and np.abs(d_low - d_high).min() > 1e-4


def test_absent_parts_are_zero_and_have_no_heads(embeddings):
    s, s0, s_prev, _, _, _ = embeddings
    success = torch.zeros(BATCH, 1, dtype=torch.bool)
    only_directional = _temporal(positional=None, directional="d1")
    assert only_directional.positional_heads is None
    out = only_directional(s, s0, s_prev, success)
    assert torch.equal(out["positional_reward"], torch.zeros(BATCH, 1))
    zero_shot = _temporal(positional="liv", directional=None)
    assert zero_shot.positional_heads is None and zero_shot.directional_heads is None
    out = zero_shot(s, s0, s_prev, success)
    assert torch.equal(out["directional_reward"], torch.zeros(BATCH, 1))
    torch.testing.assert_close(out["positional_reward"].squeeze(-1),
                               torch.cosine_similarity(s, zero_shot.goal_embedding, dim=-1))


def test_projection_option_reaches_the_functions(embeddings):
    s, s0, s_prev, _, _, _ = embeddings
    success = torch.zeros(BATCH, 1, dtype=torch.bool)
    origin = _temporal(positional="p4", directional=None, projection="origin")
    line = _temporal(positional="p4", directional=None, projection="line")
    line.load_state_dict(origin.state_dict())
    assert not torch.allclose(origin(s, s0, s_prev, success)["reward"],
                              line(s, s0, s_prev, success)["reward"])


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"k": 0}, "k=0"),
    ({"alpha": 1.5}, "alpha=1.5"),
    ({"alpha": -0.1}, "alpha=-0.1"),
    ({"rho": -1.0}, "rho=-1.0"),
    ({"lambda_": -2.0}, "lambda_=-2.0"),
    ({"positional": "p9"}, "'p9'.*furl, p1"),
    ({"directional": "furl"}, "'furl'.*d1, d2"),
    ({"projection": "middle"}, "projection='middle'"),
])
def test_configuration_errors(kwargs, message):
    with pytest.raises(ValueError, match=message):
        _temporal(**kwargs)


def test_embedding_size_mismatch_names_both_sizes():
    with pytest.raises(ValueError, match=r"shape \(7,\).*\(5,\)"):
        TemporalReward(D, torch.randn(7), torch.randn(D))
    reward = _temporal(directional="d3")
    with pytest.raises(ValueError, match="size 9.*embedding_dim=5"):
        reward(torch.randn(2, 9), torch.randn(2, 9), torch.randn(2, 9),
               torch.zeros(2, 1, dtype=torch.bool))


# --- register_reward ----------------------------------------------------------------------------

@pytest.fixture
def registry():
    """Yields the register function; removes every name it added, so other tests see built-ins."""
    added = []

    def register(name, function, **kwargs):
        register_reward(name, function, **kwargs)
        added.append(name)

    yield register
    for name in added:
        if name in IMAGE_INPUTS:
            unregister_reward(name)


def toy_positional(heads, s, *, g, **unused):
    return cosine_similarity(heads.image(s), heads.text(g)) ** 2


def toy_directional(heads, s, *, s_prev, g, b, position=None, **unused):
    position = s if position is None else position
    position, direction = torch.broadcast_tensors(position, s - s_prev)
    return cosine_similarity(heads.image(torch.cat((position, direction), -1)), heads.text(g - b))


def test_registered_rewards_build_heads_and_compute(registry, embeddings):
    s, s0, s_prev, _, _, _ = embeddings
    registry("p5", toy_positional, kind="positional")
    registry("d6", toy_directional, kind="directional", image_input="concatenated")
    assert POSITIONAL["p5"] is toy_positional and DIRECTIONAL["d6"] is toy_directional
    assert heads_input_dims("p5", 16) == (16, 16) and heads_input_dims("d6", 16) == (32, 16)
    reward = _temporal(positional="p5", directional="d6", rho=0.5, lambda_=2.0)
    assert reward.positional_heads.image_dim == D and reward.positional_heads.text_dim == D
    assert reward.directional_heads.image_dim == 2 * D and reward.directional_heads.text_dim == D
    out = reward(s, s0, s_prev, torch.zeros(BATCH, 1, dtype=torch.bool))
    g, b = reward.goal_embedding, reward.baseline_embedding
    r_p = toy_positional(reward.positional_heads, s, g=g)
    r_d = toy_directional(reward.directional_heads, s, s_prev=s_prev, g=g, b=b)
    torch.testing.assert_close(out["positional_reward"].squeeze(-1), r_p)
    torch.testing.assert_close(out["directional_reward"].squeeze(-1), r_d)
    torch.testing.assert_close(out["reward"].squeeze(-1), -1 + 0.5 * (r_p + 2.0 * r_d))


def test_zero_shot_registration_has_no_heads(registry, embeddings):
    s, s0, s_prev, _, _, _ = embeddings
    registry("liv2", lambda heads, s, *, g, **unused: -cosine_similarity(s, g),
             kind="positional", image_input=None)
    reward = _temporal(positional="liv2", directional=None)
    assert reward.positional_heads is None
    out = reward(s, s0, s_prev, torch.zeros(BATCH, 1, dtype=torch.bool))
    torch.testing.assert_close(out["positional_reward"].squeeze(-1),
                               -torch.cosine_similarity(s, reward.goal_embedding, dim=-1))
    with pytest.raises(ValueError, match="'liv2' is zero-shot"):
        heads_input_dims("liv2", 8)


def test_overwrite_replaces_and_may_change_kind(registry):
    registry("p5", toy_positional, kind="positional")
    with pytest.raises(ValueError, match="'p5' is already registered.*overwrite=True"):
        register_reward("p5", toy_positional, kind="positional")
    with pytest.raises(ValueError, match="'furl' is already registered"):
        register_reward("furl", toy_positional, kind="positional")
    registry("p5", toy_directional, kind="directional", image_input="concatenated",
             overwrite=True)
    assert "p5" not in POSITIONAL and DIRECTIONAL["p5"] is toy_directional
    assert heads_input_dims("p5", 4) == (8, 4)
    unregister_reward("p5")
    assert "p5" not in DIRECTIONAL and "p5" not in IMAGE_INPUTS
    with pytest.raises(ValueError, match="no reward 'p5' is registered"):
        unregister_reward("p5")


@pytest.mark.parametrize(("args", "kwargs", "message"), [
    (("p5", toy_positional), {"kind": "spatial"}, "kind='spatial'; expected 'positional'"),
    (("p5", toy_positional), {"kind": "positional", "image_input": "stacked"},
     "image_input='stacked'; expected 'embedding'.*'concatenated'.*None"),
    (("p5", "not a function"), {"kind": "positional"}, "is not callable"),
    (("p5", lambda heads, s: s.sum(-1)), {"kind": "positional"},
     "cannot be called the way rewards are.*expected fn\\(heads, s, \\*, g, b"),
    (("", toy_positional), {"kind": "positional"}, "name=''; expected a non-empty string"),
    ((5, toy_positional), {"kind": "positional"}, "name=5; expected a non-empty string"),
    (("None", toy_positional), {"kind": "positional"}, "name='None' is reserved"),
])
def test_register_reward_refuses_bad_input(args, kwargs, message):
    with pytest.raises(ValueError, match=message):
        register_reward(*args, **kwargs)
    assert "p5" not in IMAGE_INPUTS and "p5" not in POSITIONAL


def test_assigning_to_the_dict_directly_says_how_to_register():
    with pytest.raises(TypeError, match="POSITIONAL is a read-only view.*"
                                        "register_reward\\('p5'"):
        POSITIONAL["p5"] = toy_positional
    assert "p5" not in POSITIONAL


def test_builtins_are_registered_with_their_layouts():
    assert [name for name, layout in IMAGE_INPUTS.items() if layout is None] == ["liv"]
    assert [name for name, layout in IMAGE_INPUTS.items() if layout == "concatenated"] == [
        "d3", "d4", "d5", "d_certainty"]
    assert [name for name, layout in IMAGE_INPUTS.items() if layout == "window"] == [
        "d_sequence"]
    assert set(IMAGE_INPUTS) == set(OBJECTIVES) == {*POSITIONAL, *DIRECTIONAL}
    assert {name for name, objective in OBJECTIVES.items() if objective == "ranking"} == \
        set(POSITIONAL)
    assert [name for name, objective in OBJECTIVES.items() if objective == "certainty"] == [
        "d_certainty"]


# --- beyond the thesis: d_sequence (6.3) and the certainty of d_certainty (6.4) ------------------

def test_window_tokens_by_hand():
    """x_j = n(p) ⊕ n(w_j - w_{j-1}): the window (0,0) -> (2,0) -> (2,0) -> (2,3) at its newest
    position (2,3); the repeated entry (padding at an episode start) is a zero step."""
    window = torch.tensor([[0.0, 0.0], [2.0, 0.0], [2.0, 0.0], [2.0, 3.0]])
    p = [2 / 13 ** 0.5, 3 / 13 ** 0.5]
    torch.testing.assert_close(window_tokens(window), torch.tensor([
        [*p, 1.0, 0.0], [*p, 0.0, 0.0], [*p, 0.0, 1.0]]))
    # Another position, one vector for a batch of windows.
    tokens = window_tokens(torch.stack([window, -window]), position=torch.tensor([0.0, -4.0]))
    assert tokens.shape == (2, 3, 4)
    torch.testing.assert_close(tokens[1, 0], torch.tensor([0.0, -1.0, -1.0, 0.0]))
    with pytest.raises(ValueError, match="K >= 2"):
        window_tokens(torch.zeros(1, 3))


def test_straight_window_by_hand():
    start, end = torch.tensor([[1.0, 0.0]]), torch.tensor([4.0, 6.0])
    torch.testing.assert_close(straight_window(start, end, 4), torch.tensor(
        [[[1.0, 0.0], [2.0, 2.0], [3.0, 4.0], [4.0, 6.0]]]))
    with pytest.raises(ValueError, match="length=1"):
        straight_window(start, end, 1)


def test_d_sequence_with_two_embeddings_reads_d3_inputs():
    """K = 2: the one token of the observed, towards-goal and opposite windows the directional
    loss builds is D3's image input with k = 1 for the same three directions."""
    gen = torch.Generator().manual_seed(4)
    s_t, s_prev, s_g = (3.0 * torch.randn(BATCH, D, generator=gen) for _ in range(3))
    observed = torch.stack([s_prev, s_t], -2)

    def d3_input(position, direction):
        return torch.cat([position / position.norm(dim=-1, keepdim=True),
                          direction / direction.norm(dim=-1, keepdim=True)], -1).unsqueeze(-2)

    torch.testing.assert_close(window_tokens(observed), d3_input(s_t, s_t - s_prev))
    torch.testing.assert_close(window_tokens(straight_window(s_t, s_g, 2), position=s_t),
                               d3_input(s_t, s_g - s_t))
    torch.testing.assert_close(window_tokens(observed.flip(-2), position=s_t),
                               d3_input(s_t, s_prev - s_t))


def sequence_reward_by_definition(heads, window, position, g, b):
    """r = csim(f_I(x_1 .. x_(K-1)), f_L(g - b)) on the concatenated tokens of window_tokens."""
    return F.cosine_similarity(heads.image(window_tokens(window, position)),
                               heads.text(g - b).expand(window.shape[0], -1), dim=-1)


def test_d_sequence_is_csim_of_the_sequence_encoder_over_its_tokens(embeddings):
    """d_sequence embeds n(s_t) once per window (SequenceEncoder.forward_with_context): the
    same reward as the encoder run on the concatenated tokens of window_tokens, written out as
    r = csim(f_I(x_1 .. x_(K-1)), f_L(g - b)), at the default and at another position."""
    s, _, s_prev, _, g, b = embeddings
    heads = make_heads("d_sequence")
    window = path(s, s_prev)
    for position in (None, s_prev):
        torch.testing.assert_close(
            DIRECTIONAL["d_sequence"](heads, s, window=window, g=g, b=b, position=position),
            sequence_reward_by_definition(heads, window, position, g, b), rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="a context of size 3"):
        heads.image.forward_with_context(torch.zeros(BATCH, 3), window_tokens(window))


def test_d_sequence_of_the_straight_path_without_its_window(embeddings):
    """window=None: the straight path from s_prev to s, scored with its one token embedded once,
    equals the encoder run on the tokens of the window straight_window builds, at s_t and at
    the default position s; TemporalReward reaches it with straight_path=True only."""
    s, s0, s_prev, _, g, b = embeddings
    heads = make_heads("d_sequence")
    straight = straight_window(s_prev, s, WINDOW)
    for position in (s_prev, None):
        torch.testing.assert_close(
            DIRECTIONAL["d_sequence"](heads, s, s_prev=s_prev, g=g, b=b, position=position),
            sequence_reward_by_definition(heads, straight, position, g, b), rtol=1e-5,
            atol=1e-6)
    reward = _temporal(positional=None, directional="d_sequence", options={"window": WINDOW})
    expected = DIRECTIONAL["d_sequence"](
        reward.directional_heads, s, window=straight_window(s_prev, s, WINDOW), position=s_prev,
        g=reward.goal_embedding, b=reward.baseline_embedding)
    torch.testing.assert_close(reward.directional_reward(s, s_prev, s0, position=s_prev,
                                                         straight_path=True),
                               expected, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="reads the window of the last 4 embeddings"):
        reward.directional_reward(s, s_prev, s0)
    with pytest.raises(ValueError, match="pass window=None with it"):
        reward.directional_reward(s, s_prev, s0, window=straight, straight_path=True)


def test_sequence_encoder_embeds_broadcast_tokens_once():
    """Tokens expanded over the sequence take the embed-once path and give the encoder's output
    on the same tokens materialised, gradients included."""
    torch.manual_seed(3)
    encoder = SequenceEncoder(token_dim=6, length=5, hidden_dim=16, out_dim=4, width=8,
                              heads=2)
    context, token = torch.randn(7, 2), torch.randn(7, 1, 4, requires_grad=True)
    expanded = token.expand(7, 5, 4)
    assert expanded.stride(-2) == 0
    fast = encoder.forward_with_context(context, expanded)
    (fast_grad,) = torch.autograd.grad(fast.sum(), token)
    materialised = torch.cat([context.unsqueeze(-2).expand(7, 5, 2), expanded], -1).contiguous()
    slow = encoder(materialised)
    (slow_grad,) = torch.autograd.grad(slow.sum(), token)
    torch.testing.assert_close(fast, slow, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(fast_grad, slow_grad, rtol=1e-5, atol=1e-6)
    # Norms that differ per token keep every token apart, broadcast tokens or not.
    norms = torch.rand(7, 5, 1) + 0.5
    torch.testing.assert_close(
        encoder.forward_with_context(context, expanded, norms),
        encoder(torch.cat([context.unsqueeze(-2).expand(7, 5, 2), expanded / norms], -1)),
        rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match=r"token_norms of shape \(7, 5\); expected"):
        encoder.forward_with_context(context, expanded, norms.squeeze(-1))


def test_sequence_encoder_layer_written_out_is_torchs_layer():
    """SequenceEncoder runs its nn.TransformerEncoderLayer's function on the layer's own
    parameters, without nn.MultiheadAttention: the same outputs and parameter gradients as the
    torch module, with and without gradients."""
    torch.manual_seed(5)
    encoder = SequenceEncoder(token_dim=6, length=5, hidden_dim=16, out_dim=4, width=8,
                              heads=2)
    x = torch.randn(9, 5, 8)
    mine, torchs = encoder._encoder_layer(x), encoder.layer(x)
    torch.testing.assert_close(mine, torchs, rtol=1e-5, atol=1e-6)
    parameters = list(encoder.layer.parameters())
    for a, b in zip(torch.autograd.grad(mine.square().sum(), parameters),
                    torch.autograd.grad(torchs.square().sum(), parameters), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)
    with torch.no_grad():
        torch.testing.assert_close(encoder._encoder_layer(x), encoder.layer(x), rtol=1e-5,
                                   atol=1e-6)


def test_d_sequence_reads_the_order_of_the_steps(embeddings):
    s, s0, s_prev, _, g, b = embeddings
    heads = make_heads("d_sequence")
    window = path(s, s_prev)
    shuffled = window[:, [0, 2, 1, 3]]  # the same steps' positions, another order
    forward = DIRECTIONAL["d_sequence"](heads, s, window=window, g=g, b=b)
    assert not torch.allclose(forward, DIRECTIONAL["d_sequence"](heads, s, window=shuffled,
                                                                 g=g, b=b))
    with pytest.raises(ValueError, match="needs window"):
        DIRECTIONAL["d_sequence"](heads, s, g=g, b=b)
    with pytest.raises(ValueError, match=r"expected \[\.\.\., 3, 10\]"):
        DIRECTIONAL["d_sequence"](heads, s, window=path(s, s_prev)[:, 1:], g=g, b=b)


def certainty_references():
    """Two positives and two negatives at the position e1: the positives moved along e2, the
    negatives along e3."""
    e1, e2, e3 = torch.eye(3)
    positions = torch.stack([e1, e1, e1, e1])
    directions = torch.stack([e2, e2, e3, e3])
    labels = torch.tensor([1.0, 1.0, -1.0, -1.0])
    return positions, directions, labels


def test_reference_scales_by_hand():
    positions, directions, _ = certainty_references()
    # Positions all equal: median distance 0, floored at EPS. Directions: of the 12 ordered
    # distinct pairs, 4 are equal (distance 0) and 8 orthogonal (distance 1): median 1.
    torch.testing.assert_close(reference_scales(positions, directions),
                               torch.tensor([1e-8, 1.0]))
    torch.testing.assert_close(reference_scales(positions[:1], directions[:1]), torch.ones(2))


def test_certainty_is_positive_negative_or_unsure_by_hand():
    """A direction seen only in positives gets a positive certainty, one seen only in negatives
    a negative one, an unseen one (the opposite direction, or another position) about 0."""
    positions, directions, labels = certainty_references()
    e1, e2, e3 = torch.eye(3)
    queries = torch.stack([e1, e1, e1, e2]), torch.stack([e2, e3, -e2, e2])

    def certainty(bandwidth, **kwargs):
        return direction_certainty(*queries, positions, directions, labels,
                                   bandwidth=bandwidth, prior=1.0, **kwargs)

    # Scales [EPS, 1] (above), beta = 0.1: kappa = 1 for the same position and direction,
    # exp(-10) for an orthogonal direction, exp(-20) for the opposite one, ~0 elsewhere.
    near, far = np.exp(-10.0), np.exp(-20.0)
    expected = [(2 - 2 * near) / (3 + 2 * near), (2 * near - 2) / (3 + 2 * near),
                (2 * far - 2 * near) / (1 + 2 * far + 2 * near), 0.0]
    np.testing.assert_allclose(certainty(0.1).numpy(), expected, atol=1e-7)
    assert certainty(0.1)[0] > 0.6 and certainty(0.1)[1] < -0.6
    assert abs(certainty(0.1)[2]) < 1e-3 and abs(certainty(0.1)[3]) < 1e-3
    # Explicit scales [1, 1] and beta = 1: the position kernel matters too (e2 vs e1: exp(-1)).
    wide = certainty(1.0, scales=torch.ones(2)).numpy()
    a, c = np.exp(-1.0), np.exp(-2.0)
    np.testing.assert_allclose(wide, [(2 - 2 * a) / (3 + 2 * a), (2 * a - 2) / (3 + 2 * a),
                                      (2 * c - 2 * a) / (1 + 2 * c + 2 * a),
                                      (2 * a - 2 * c) / (1 + 2 * a + 2 * c)], rtol=1e-6)
    # Leave-one-out: the first positive without itself has one positive neighbour left.
    exclude = torch.zeros(4, 4, dtype=torch.bool)
    exclude[0, 0] = True
    assert certainty(0.1, exclude=exclude)[0].item() == pytest.approx(
        (1 - 2 * near) / (2 + 2 * near))
    # No references at all: unsure everywhere.
    assert torch.equal(direction_certainty(*queries, positions[:0], directions[:0], labels[:0]),
                       torch.zeros(4))
    with pytest.raises(ValueError, match="prior=0"):
        direction_certainty(*queries, positions, directions, labels, prior=0)


def test_certainty_scaling_multiplies_the_directional_reward_by_the_certainty(embeddings):
    """certainty_scaling: forward's r_D is |t(s_t, Δs_t)| r_D3, the losses' directional_reward
    stays D3; the references are part of the state_dict (resume)."""
    s, s0, s_prev, _, _, _ = embeddings
    reward = _temporal(positional=None, directional="d3", certainty_scaling=True)
    success = torch.zeros(BATCH, 1, dtype=torch.bool)
    assert torch.equal(reward(s, s0, s_prev, success)["directional_reward"],
                       torch.zeros(BATCH, 1))  # no references yet: unsure everywhere
    # The first two states' moves were seen in positives, the last two in negatives.
    references = (s, s - s_prev, torch.tensor([1.0, 1.0, -1.0, -1.0]))
    reward.certainty.remember(*references)
    r_d3 = reward.directional_reward(s, s_prev, s0)
    t = direction_certainty(s, s - s_prev, *references,
                            bandwidth=reward.options["certainty_bandwidth"],
                            prior=reward.options["certainty_prior"])
    assert (t[:2] > 0.4).all() and (t[2:] < -0.4).all()
    torch.testing.assert_close(reward(s, s0, s_prev, success)["directional_reward"].squeeze(-1),
                               r_d3 * t.abs())
    resumed = _temporal(positional=None, directional="d3", certainty_scaling=True)
    resumed.load_state_dict(reward.state_dict())
    assert resumed.certainty.labels.numel() == 4
    torch.testing.assert_close(resumed(s, s0, s_prev, success)["directional_reward"],
                               reward(s, s0, s_prev, success)["directional_reward"])
    with pytest.raises(ValueError, match="set directional too"):
        _temporal(positional="furl", directional=None, certainty_scaling=True)


def test_window_reward_needs_its_window(embeddings):
    s, s0, s_prev, _, _, _ = embeddings
    reward = _temporal(positional="furl", directional="d_sequence", options={"window": WINDOW})
    assert reward.window_length == WINDOW
    assert reward.directional_heads.image.length == WINDOW - 1
    assert _temporal(directional="d3").window_length is None
    success = torch.zeros(BATCH, 1, dtype=torch.bool)
    window = path(s, s_prev)
    out = reward(s, s0, s_prev, success, window=window)
    torch.testing.assert_close(out["directional_reward"].squeeze(-1), DIRECTIONAL["d_sequence"](
        reward.directional_heads, s, window=window, g=reward.goal_embedding,
        b=reward.baseline_embedding))
    with pytest.raises(ValueError, match="reads the window of the last 4 embeddings"):
        reward(s, s0, s_prev, success)
    with pytest.raises(ValueError, match=r"expected \[\.\.\., 4, 5\]"):
        reward(s, s0, s_prev, success, window=window[:, 1:])
    with pytest.raises(ValueError, match=r"option window=1 of reward 'd_sequence'; expected an "
                                         r"integer >= 2"):
        _temporal(directional="d_sequence", options={"window": 1})


def test_the_built_in_hyperparameters_are_registered_options(registry, embeddings):
    """d_sequence's K and d_certainty's beta and c are registry options, with the defaults of
    temporal_torchrl.defaults, set as any reward's are (options=); a window reward or a
    certainty-trained reward of one's own has them too. d_sequence's function is not passed K
    (it receives the window itself as ``window``); the others receive their options."""
    from temporal_torchrl import defaults
    from temporal_torchrl.objectives import CertaintyLoss

    s, s0, s_prev, _, _, _ = embeddings
    certainty = {"certainty_bandwidth": defaults.CERTAINTY_BANDWIDTH,
                 "certainty_prior": defaults.CERTAINTY_PRIOR}
    assert dict(REWARDS["d_sequence"].options) == {"window": defaults.WINDOW_LENGTH}
    assert dict(REWARDS["d_certainty"].options) == certainty
    assert all(not REWARDS[name].options for name in ("furl", "p1", "d3", "d5", "liv"))
    assert _temporal(directional="d_sequence").window_length == defaults.WINDOW_LENGTH
    twelve = _temporal(directional="d_sequence", options={"window": 12})
    assert twelve.window_length == 12 and twelve.directional_heads.image.length == 11
    assert twelve.part_options("d_sequence") == {}
    wide = _temporal(directional="d_certainty", options={"certainty_bandwidth": 0.3})
    assert wide.options == {**certainty, "certainty_bandwidth": 0.3}
    assert wide.part_options("d_certainty") == wide.options
    assert CertaintyLoss(wide, torch.randn(D), stage=1).reward.options["certainty_bandwidth"] \
        == 0.3
    # certainty_scaling gives the reward it scales the certainty options, for its estimate.
    scaled = _temporal(directional="d3", certainty_scaling=True,
                       options={"certainty_prior": 2, "certainty_bandwidth": 0.2})
    assert (scaled.certainty.bandwidth, scaled.certainty.prior) == (0.2, 2.0)
    assert scaled.part_options("d3") == {}
    with pytest.raises(ValueError, match="options 'window': not an option of furl or d3"):
        _temporal(options={"window": 12})
    with pytest.raises(ValueError, match="options 'certainty_prior': not an option of furl or "
                                         "d3"):
        _temporal(options={"certainty_prior": 2.0})
    with pytest.raises(ValueError, match=r"option certainty_prior=0\.0 of reward "
                                         r"'certainty_scaling'; expected a number > 0"):
        _temporal(directional="d3", certainty_scaling=True, options={"certainty_prior": 0})
    with pytest.raises(ValueError, match=r"option window=12\.0 of reward 'd_sequence'; expected "
                                         r"an integer >= 2"):
        _temporal(directional="d_sequence", options={"window": 12.0})
    # Rewards of one's own: by their layout and objective, alike.
    seen = {}

    def window_reward(heads, s, *, window=None, **keywords):
        seen.update(keywords)
        return DIRECTIONAL["d_sequence"](heads, s, window=window, **keywords)

    registry("d6", window_reward, kind="directional", image_input="window")
    registry("d7", toy_directional, kind="directional", image_input="concatenated",
             objective="certainty")
    assert dict(REWARDS["d6"].options) == {"window": defaults.WINDOW_LENGTH}
    assert dict(REWARDS["d7"].options) == certainty
    own = _temporal(positional=None, directional="d6", options={"window": 3})
    own.directional_reward(s, s_prev, s0, window=path(s, s_prev)[:, -3:])
    assert own.window_length == 3 and "window" not in seen
    for reserved in ("window", "certainty_prior"):
        with pytest.raises(ValueError, match=f"option '{reserved}' is"):
            register_reward("d8", toy_directional, kind="directional",
                            image_input="concatenated", options={reserved: 4.0})


def test_objectives_are_registered_and_checked(registry):
    assert objective_of("d3") == "directional" and objective_of("d_certainty") == "certainty"
    registry("d6", toy_directional, kind="directional", image_input="concatenated",
             objective="certainty")
    assert objective_of("d6") == "certainty"
    with pytest.raises(ValueError, match="objective='certainty'; a positional reward is "
                                         "trained with one of ranking"):
        register_reward("p6", toy_positional, kind="positional", objective="certainty")
    with pytest.raises(ValueError, match="objective='certainty' needs a reward of one direction"):
        register_reward("d7", toy_directional, kind="directional", image_input="window",
                        objective="certainty")
    with pytest.raises(ValueError, match="image_input='window' is for directional rewards"):
        register_reward("p6", toy_positional, kind="positional", image_input="window")
    with pytest.raises(ValueError, match="Unknown reward variant 'd9'"):
        objective_of("d9")


def scaled_positional(heads, s, *, g, scale, **unused):
    """A positional reward with an option of its own."""
    return scale * cosine_similarity(heads.image(s), heads.text(g))


def test_a_reward_declares_its_options_and_receives_their_values(registry, embeddings):
    s, s0, s_prev, _, _, _ = embeddings
    registry("p6", scaled_positional, kind="positional", options={"scale": 2.0, "tag": None})
    registry("d6", toy_directional, kind="directional", image_input="concatenated",
             options={"scale": 1.0, "steps": 3, "clipped": False})
    assert dict(REWARDS["p6"].options) == {"scale": 2.0, "tag": None}
    success = torch.zeros(BATCH, 1, dtype=torch.bool)
    default = _temporal(positional="p6", directional=None)
    assert default.options == {"scale": 2.0, "tag": None}
    expected = 2.0 * cosine_similarity(default.positional_heads.image(s),
                                       default.positional_heads.text(default.goal_embedding))
    torch.testing.assert_close(default(s, s0, s_prev, success)["positional_reward"].squeeze(-1),
                               expected)
    # An int is taken for a float; an option both parts declare goes to both.
    given = _temporal(positional="p6", directional="d6", options={"scale": 3, "steps": 5})
    assert given.options == {"scale": 3.0, "tag": None, "steps": 5, "clipped": False}
    assert given.part_options("p6") == {"scale": 3.0, "tag": None}
    assert given.part_options("d3") == {}  # a built-in declares none
    assert "options={'scale': 3.0" in repr(given)
    halved = _temporal(positional="p6", directional="d6", options={"scale": 2})
    halved.load_state_dict(given.state_dict())
    torch.testing.assert_close(given.positional_reward(s), 1.5 * halved.positional_reward(s))
    with pytest.raises(ValueError, match=r"options 'scales': not an option of p6 or d6; their "
                                         r"options: scale, tag, steps, clipped"):
        _temporal(positional="p6", directional="d6", options={"scales": 3.0})
    with pytest.raises(ValueError, match="not an option of furl or d3; their options: none"):
        _temporal(options={"scale": 3.0})
    for bad, expected_type in (({"steps": 2.5}, "int"), ({"clipped": 1}, "bool"),
                               ({"scale": "big"}, "float")):
        with pytest.raises(ValueError, match=f"expected a {expected_type} like d6's default"):
            _temporal(positional="p6", directional="d6", options=bad)


def test_options_are_checked_when_registered(registry):
    with pytest.raises(ValueError, match="option 'alpha' is one of the keywords"):
        register_reward("p6", scaled_positional, kind="positional", options={"alpha": 0.5})
    with pytest.raises(ValueError, match="option name 'two words'"):
        register_reward("p6", scaled_positional, kind="positional", options={"two words": 1})
    with pytest.raises(ValueError, match=r"option scale=\[1, 2\]; a default is a bool"):
        register_reward("p6", scaled_positional, kind="positional", options={"scale": [1, 2]})
    with pytest.raises(ValueError, match="options=3; expected a dict"):
        register_reward("p6", scaled_positional, kind="positional", options=3)
    # The function must take its options (here scale, as a keyword without **unused).
    with pytest.raises(ValueError, match="cannot be called the way rewards are"):
        register_reward("p6", lambda heads, s, *, g, b, s0, s_prev, alpha, projection, position,
                        window: s.sum(-1), kind="positional", options={"scale": 1.0})
    assert "p6" not in REWARDS


def test_a_reward_brings_its_own_loss(registry):
    from temporal_torchrl.objectives import (
        OBJECTIVE_LOSSES,
        DirectionalLoss,
        finetuning_losses,
        loss_class,
    )

    class TwiceTheDirectionalLoss(DirectionalLoss):
        def forward(self, tensordict):
            out = super().forward(tensordict)
            out[self.loss_key] = 2 * out[self.loss_key]
            return out

    registry("d6", toy_directional, kind="directional", image_input="concatenated",
             loss=TwiceTheDirectionalLoss)
    assert objective_of("d6") == "TwiceTheDirectionalLoss"
    assert loss_class("d6") is TwiceTheDirectionalLoss
    assert {name: loss_class(name) for name in ("furl", "d3", "d_certainty")} == {
        "furl": OBJECTIVE_LOSSES["ranking"], "d3": OBJECTIVE_LOSSES["directional"],
        "d_certainty": OBJECTIVE_LOSSES["certainty"]}
    reward = _temporal(positional="furl", directional="d6")
    ranking, directional = finetuning_losses(reward, torch.randn(D), stage=1, delta=0.3,
                                             same_position=False)
    assert ranking.delta == 0.3 and type(directional) is TwiceTheDirectionalLoss
    assert directional.same_position is False  # the settings its __init__ takes
    with pytest.raises(ValueError, match="zero-shot reward"):
        register_reward("p6", toy_positional, kind="positional", image_input=None,
                        loss=TwiceTheDirectionalLoss)
    with pytest.raises(ValueError, match="expected a subclass of "
                                         "temporal_torchrl.objectives.FinetuningLoss"):
        register_reward("d7", toy_directional, kind="directional", image_input="concatenated",
                        loss=torch.nn.MSELoss)


def test_reward_options_from_a_config(registry):
    from omegaconf import OmegaConf

    from temporal_torchrl.configs import RecipeConfig
    from temporal_torchrl.rewards import reward_options

    registry("p6", scaled_positional, kind="positional", options={"scale": 2.0})
    registry("d6", toy_directional, kind="directional", image_input="concatenated",
             options={"steps": 3})
    config = OmegaConf.to_container(OmegaConf.structured(RecipeConfig))
    config["reward"].update(positional="p6", directional="d6", options={"scale": 3, "steps": 4})
    assert reward_options(config)["options"] == {"scale": 3, "steps": 4}
    # One variant scored alone gets its own options only.
    assert reward_options(config, variant="p6")["options"] == {"scale": 3}
    assert reward_options(config, variant="d3")["options"] == {}
    # A run older than reward.options: none.
    del config["reward"]["options"]
    assert reward_options(config)["options"] == {}


def test_a_config_with_the_deprecated_reward_keys_means_their_options():
    """A run's config.json saved before d_sequence's and d_certainty's hyperparameters became
    reward options holds reward.window, reward.certainty_bandwidth and reward.certainty_prior,
    at their defaults unless changed: at the defaults they set nothing (the reward is the
    default one), changed they set the option of the same name; set both ways and differing,
    refused naming both."""
    from omegaconf import OmegaConf

    from temporal_torchrl.configs import RecipeConfig
    from temporal_torchrl.rewards import reward_options
    from temporal_torchrl.rewards.config import with_moved_options

    config = OmegaConf.to_container(OmegaConf.structured(RecipeConfig))
    del config["reward"]["options"]
    config["reward"].update(directional="d_sequence", window=8, certainty_bandwidth=0.1,
                            certainty_prior=1.0)
    assert reward_options(config)["options"] == {}
    assert with_moved_options(config)["reward"] == {
        **config["reward"], "window": None, "certainty_bandwidth": None, "certainty_prior": None,
        "options": {}}
    config["reward"]["window"] = 12
    assert reward_options(config)["options"] == {"window": 12}
    assert reward_options(config, variant="d_certainty")["options"] == {}
    assert with_moved_options(config)["reward"]["options"] == {"window": 12}
    config["reward"]["options"] = {"window": 12}
    assert reward_options(config)["options"] == {"window": 12}
    config["reward"]["options"] = {"window": 10}
    with pytest.raises(ValueError, match=r"config reward\.window=12 and reward\.options\."
                                         r"window=10 disagree: reward\.window is the deprecated "
                                         r"spelling of reward\.options\.window"):
        reward_options(config)


def test_the_old_hyperparameter_keywords_still_work_for_a_release():
    D = 8
    goal, baseline = torch.randn(D), torch.randn(D)
    with pytest.warns(FutureWarning, match=r"TemporalReward\(window_length=\.\.\.\) is deprecated"
                                           r".*pass options=\{'window': 6\}"):
        reward = TemporalReward(D, goal, baseline, directional="d_sequence", window_length=6)
    assert reward.window_length == 6
    assert reward.options["window"] == TemporalReward(
        D, goal, baseline, directional="d_sequence", options={"window": 6}).options["window"]
    with pytest.raises(TypeError, match="unexpected keyword"):
        TemporalReward(D, goal, baseline, windw=3)
    with pytest.raises(ValueError, match="disagree"), pytest.warns(FutureWarning):
        TemporalReward(D, goal, baseline, directional="d_sequence", window_length=6,
                       options={"window": 4})
