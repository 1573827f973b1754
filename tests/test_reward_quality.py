"""Offline reward-quality benchmark: metrics on hand-made inputs, scoring of hand-made rewards,
the split by episode, the dataset cache and a tiny end-to-end run of recipes/evaluate_rewards.py."""

import json
from pathlib import Path

import evaluate_rewards
import pytest
import torch
from helpers import synthetic_episode
from hydra import compose, initialize_config_dir
from tensordict import TensorDict

from temporal_torchrl.encoders import load_encoder
from temporal_torchrl.reward_quality import (
    DatasetSpec,
    auroc,
    direction_accuracy,
    finetune_reward,
    load_or_collect,
    make_finetuning_buffer,
    prepare_task,
    score_reward,
    spearman_correlation,
    split_by_episode,
    task_config,
    value_order_correlation,
)
from temporal_torchrl.reward_quality import dataset as dataset_module
from temporal_torchrl.rewards import (
    TemporalReward,
    register_reward,
    single_part,
    unregister_reward,
)

RECIPES = Path(__file__).resolve().parents[1] / "recipes"


# --------------------------------------------------------------------------- metrics
def test_value_order_correlation_of_rising_falling_and_tied_rewards():
    assert value_order_correlation(torch.tensor([0.1, 0.3, 0.35, 0.9])) == pytest.approx(1.0)
    assert value_order_correlation(torch.tensor([5.0, 2.0, 1.0, -3.0])) == pytest.approx(-1.0)
    # Ranks [1, 3, 2] against [1, 2, 3]: 1 - 6 * (0 + 1 + 1) / (3 * (9 - 1)) = 0.5.
    assert value_order_correlation(torch.tensor([1.0, 9.0, 4.0])) == pytest.approx(0.5)
    # Ties share their mean rank: [1, 2.5, 2.5, 4] against [1, 2, 3, 4] gives 4.5 / sqrt(22.5).
    assert value_order_correlation(torch.tensor([0.1, 0.2, 0.2, 0.5])) == pytest.approx(
        4.5 / 22.5 ** 0.5)
    assert value_order_correlation(torch.full((6,), 0.3)) == 0.0


def test_spearman_is_pearson_of_ranks():
    x = torch.tensor([3.0, 1.0, 4.0, 1.5, 5.0, 9.0])
    y = torch.tensor([2.0, 7.0, 1.0, 8.0, 2.5, 0.5])
    ranks_x = torch.tensor([3.0, 1.0, 4.0, 2.0, 5.0, 6.0])
    ranks_y = torch.tensor([3.0, 5.0, 2.0, 6.0, 4.0, 1.0])
    expected = torch.corrcoef(torch.stack([ranks_x, ranks_y]))[0, 1]
    assert spearman_correlation(x, y) == pytest.approx(float(expected))


def test_auroc_of_hand_made_scores():
    assert auroc(torch.tensor([0.6, 0.7, 0.9]), torch.tensor([0.1, 0.5])) == 1.0
    assert auroc(torch.tensor([0.1, 0.2]), torch.tensor([0.3, 0.9, 0.4])) == 0.0
    # Pairs: 0.9 beats both, 0.8 beats 0.1 only: 3 of 4.
    assert auroc(torch.tensor([0.9, 0.8]), torch.tensor([0.1, 0.85])) == 0.75
    # (1 > 0.5), (1 > 0), (0.5 = 0.5: one half), (0.5 > 0): 3.5 of 4.
    assert auroc(torch.tensor([1.0, 0.5]), torch.tensor([0.5, 0.0])) == 0.875
    assert auroc(torch.full((3,), 0.2), torch.full((5,), 0.2)) == 0.5


def test_direction_accuracy_of_hand_made_rewards():
    forward = torch.tensor([0.9, 0.2, 0.5, 0.4])
    assert direction_accuracy(forward, forward - 0.1) == 1.0
    assert direction_accuracy(forward, forward) == 0.5
    # Wins, a loss, a tie, a win: (1 + 0 + 0.5 + 1) / 4.
    assert direction_accuracy(forward, torch.tensor([0.1, 0.3, 0.5, 0.3])) == 0.625


@pytest.mark.parametrize(("call", "message"), [
    (lambda: auroc(torch.tensor([]), torch.tensor([0.1])), "at least 1"),
    (lambda: auroc(torch.tensor([float("nan")]), torch.tensor([0.1])), "NaN"),
    (lambda: direction_accuracy(torch.ones(3), torch.ones(2)), "same frames"),
    (lambda: value_order_correlation(torch.ones(2, 2)), "one dimension"),
])
def test_metrics_refuse_bad_input(call, message):
    with pytest.raises(ValueError, match=message):
        call()


# --------------------------------------------------------------------------- scoring
D = 4
AXIS = torch.tensor([1.0, 0.0, 0.0, 0.0])


def progress_episode(progress: torch.Tensor, successes=()) -> TensorDict:
    """An embedded episode whose states s_0 .. s_T sit at ``progress`` along AXIS, successful
    after the transitions ``successes`` (their ("next", "success") is True)."""
    steps = progress.numel() - 1
    offsets = 0.01 * torch.randn(steps + 1, D)
    offsets[:, 0] = 0
    states = progress.unsqueeze(-1) * AXIS + offsets + torch.tensor([0.0, 1.0, 0.0, 0.0])
    next_success = torch.zeros(steps, dtype=torch.bool)
    next_success[list(successes)] = True
    return synthetic_episode(states, next_success, actions=torch.zeros(steps, 4))


def progress(heads, s, **unused):
    return s[..., 0]


def regress(heads, s, **unused):
    return -s[..., 0]


def forward_direction(heads, s, *, s_prev=None, **unused):
    return s[..., 0] - s_prev[..., 0]


def order_blind(heads, s, **unused):
    return s[..., 0]


HAND_MADE = {"rq_progress": (progress, "positional"), "rq_regress": (regress, "positional"),
             "rq_forward": (forward_direction, "directional"),
             "rq_blind": (order_blind, "directional")}


@pytest.fixture
def hand_made_rewards():
    for name, (function, kind) in HAND_MADE.items():
        register_reward(name, function, kind=kind, image_input=None)
    yield
    for name in HAND_MADE:
        unregister_reward(name)


@pytest.fixture
def held_out_episodes():
    # Successful episodes rise to success at step 30, then fall back (after the success, which
    # scoring must not read); failed ones stay below every successful state.
    successful = [progress_episode(torch.cat([torch.linspace(0.1, 1.0, 31),
                                              torch.linspace(0.9, 0.0, 10)]),
                                   range(first, first + 3))
                  for first in (29, 30)]
    failed = [progress_episode(-torch.rand(21)) for _ in range(2)]
    return successful, failed


def score(variant, episodes):
    reward = TemporalReward(D, torch.ones(D), torch.zeros(D), **single_part(variant), k=3)
    return score_reward(reward, *episodes)


def test_scores_of_hand_made_rewards(hand_made_rewards, held_out_episodes):
    rising = score("rq_progress", held_out_episodes)
    assert rising.kind == "positional"
    # The first episode is read up to s_30 (strictly rising): VOC 1. The second succeeds one
    # step later and is read up to s_31 = 0.9, which ranks 27th of 31: d^2 sums to
    # 4 * 1 + 4^2 = 20, so its VOC is 1 - 6 * 20 / (31 * (31^2 - 1)).
    second = 1 - 6 * 20 / (31 * (31**2 - 1))
    assert rising.value_order_correlation == pytest.approx((1.0 + second) / 2)
    assert rising.value_order_correlation_std == pytest.approx((1.0 - second) / 2)
    assert rising.auroc == 1.0
    assert rising.direction_accuracy is None
    falling = score("rq_regress", held_out_episodes)
    assert falling.value_order_correlation == pytest.approx(-(1.0 + second) / 2)
    assert falling.auroc == 0.0
    assert rising.positive_steps == 30 + 31 and rising.negative_steps == 2 * 20


def test_direction_accuracy_of_hand_made_directional_rewards(hand_made_rewards,
                                                              held_out_episodes):
    successful, failed = held_out_episodes
    first_only = ([successful[0]], failed)  # rises strictly up to its success
    forward = score("rq_forward", first_only)
    assert forward.kind == "directional" and forward.direction_accuracy == 1.0
    assert forward.value_order_correlation is None
    assert score("rq_blind", first_only).direction_accuracy == 0.5


def test_scoring_refuses_a_reward_with_two_parts(held_out_episodes):
    from temporal_torchrl.rewards import TemporalReward

    reward = TemporalReward(D, torch.ones(D), torch.zeros(D), positional="furl",
                            directional="d3")
    with pytest.raises(ValueError, match="exactly one part"):
        score_reward(reward, *held_out_episodes)


def test_finetuning_trains_heads_towards_the_labels(held_out_episodes):
    successful, failed = held_out_episodes
    buffer = make_finetuning_buffer([*successful, *failed], k=3, gap=3)
    torch.manual_seed(0)
    reward = TemporalReward(D, torch.ones(D), torch.zeros(D), **single_part("furl"), k=3)
    before = score_reward(reward, successful, failed).auroc
    losses = finetune_reward(reward, buffer, successful[0]["next", "embedding"][29],
                             updates=150, batch_size=32, lr=1e-2)
    assert set(losses) == {"loss_positional"}
    after = score_reward(reward, successful, failed)
    assert after.auroc > max(before, 0.9)
    stage_one = make_finetuning_buffer([*successful, *failed], stage=1, k=3)
    assert stage_one.stage == 1 and stage_one.num_episodes == 2


# --------------------------------------------------------------------------- dataset
def test_split_by_episode_keeps_each_episode_on_one_side():
    kinds = ["expert"] * 7 + ["random"] * 3 + ["failed_expert"] * 2 + ["random"]
    train, held_out = split_by_episode(kinds, 0.33, seed=3)
    assert not set(train) & set(held_out)
    assert sorted(train + held_out) == list(range(len(kinds)))
    held_kinds = [kinds[i] for i in held_out]
    # round(0.33 * n) per kind, at least one, never all: 2 experts, 1 random, 1 failed expert.
    assert sorted(held_kinds) == ["expert", "expert", "failed_expert", "random"]
    assert split_by_episode(kinds, 0.33, seed=3) == (train, held_out)
    assert split_by_episode(kinds, 0.33, seed=4) != (train, held_out)
    with pytest.raises(ValueError, match="held_out_fraction"):
        split_by_episode(kinds, 1.0)


def test_dataset_is_collected_once_then_read_from_the_cache(tmp_path, monkeypatch):
    encoder = load_encoder("state", dim=8)
    spec = DatasetSpec("button-press-topdown", max_episode_steps=15, expert_episodes=2,
                       random_episodes=1, failed_expert_episodes=2)
    first = load_or_collect(spec, encoder, tmp_path)
    assert first.kinds == ["expert", "expert", "random", "failed_expert", "failed_expert"]
    assert first.successful == [True, True, False, False, False]
    assert first.noises[-1] >= spec.failure_noise and first.noises[2] is None

    def collect_again(*args, **kwargs):
        raise AssertionError("the cached dataset was collected again")

    monkeypatch.setattr(dataset_module, "collect_reward_dataset", collect_again)
    second = load_or_collect(spec, encoder, tmp_path)
    assert second.source.endswith(".pt") and second.kinds == first.kinds
    for cached, collected in zip(second.episodes, first.episodes, strict=True):
        assert torch.equal(cached["next", "embedding"], collected["next", "embedding"])
    with pytest.raises(AssertionError, match="collected again"):
        load_or_collect(spec, load_encoder("state", dim=8, seed=1), tmp_path)


@pytest.mark.parametrize(("counts", "message"), [
    ({"expert_episodes": 1}, r"expert_episodes=1; expected an integer >= 2"),
    ({"random_episodes": 1, "failed_expert_episodes": 1}, "at least 2")])
def test_dataset_spec_refuses_too_few_episodes(counts, message):
    with pytest.raises(ValueError, match=message):
        DatasetSpec("push", **counts)


# --------------------------------------------------------------------------- recipe
TINY = ["encoder.name=state", "+encoder.options.dim=16", "env.task=button-press-topdown",
        "env.max_episode_steps=20", "dataset.expert_episodes=3", "dataset.random_episodes=2",
        "dataset.failed_expert_episodes=2", "finetune.updates=10", "reward.batch_size=16",
        "reward.gap=3", "threads=1"]

MY_REWARD = '''
from temporal_torchrl.rewards import cosine_similarity, register_reward

def progress_since_start(heads, s, *, g, s0=None, **unused):
    return cosine_similarity(heads.image(s) - heads.image(s0), heads.text(g))

register_reward("rq_p5", progress_since_start, kind="positional", overwrite=True)
'''


def config(tmp_path, *overrides):
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        return compose("evaluate_rewards", overrides=[
            *TINY, f"output_dir={tmp_path / 'out'}", f"dataset.cache_dir={tmp_path / 'cache'}",
            *overrides])


@pytest.fixture
def my_reward_module(tmp_path):
    module = tmp_path / "my_rewards.py"
    module.write_text(MY_REWARD)
    yield module
    unregister_reward("rq_p5")


# The scores of the module docstring of temporal_torchrl.reward_quality.scoring, written out in
# float64 from the thesis's equations (chapter 4) on the heads' own layers, to check the recipe's
# rows against: states s_1 .. s_L of a successful episode (L = its first success state), s_1 ..
# s_T of a failed one, s_(t-k) clamped to s_0, the backward episode's previous frame s_(t+k)
# clamped to s_L.
def average_ranks(values: torch.Tensor) -> torch.Tensor:
    """1-based ranks, ties sharing their mean rank."""
    values = values.double()
    return torch.stack([(values < value).sum() + ((values == value).sum() + 1) / 2
                        for value in values]).double()


def rank_correlation_with_time(values: torch.Tensor) -> float:
    x, t = average_ranks(values), torch.arange(1, len(values) + 1, dtype=torch.float64)
    x, t = x - x.mean(), t - t.mean()
    return float((x * t).sum() / (x.norm() * t.norm())) if x.norm() > 0 else 0.0


def pair_auroc(positive: torch.Tensor, negative: torch.Tensor) -> float:
    greater = (positive[:, None] > negative[None, :]).double().mean()
    return float(greater + 0.5 * (positive[:, None] == negative[None, :]).double().mean())


def unit64(x: torch.Tensor) -> torch.Tensor:
    return x / x.norm(dim=-1, keepdim=True)


def csim64(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    return (unit64(x) * unit64(y)).sum(-1)


def regularised64(x: torch.Tensor, g: torch.Tensor, b: torch.Tensor, alpha: float):
    """Eq. 4.5's alpha proj_L x + (1 - alpha) x, L the direction g - b through the origin."""
    d = g - b
    return alpha * ((x @ d) / (d @ d)).unsqueeze(-1) * d + (1 - alpha) * x


def thesis_reward(variant, heads, s, s_prev, g, b, alpha):
    """r(s_t) of the thesis equation of ``variant`` (liv, p3, p4: 4.2.2; d5: 4.3.2), float64."""
    g, b = g.double(), b.double()
    if heads is not None:
        def f_image(x):
            return heads.image(x.float()).double()

        def f_text(x):
            return heads.text(x.float()).double()
    if variant == "liv":
        return csim64(s, g)
    if variant == "p3":
        u, v_g, v_b = unit64(f_image(s)), unit64(f_text(g)), unit64(f_text(b))
        return 1 - 0.5 * (regularised64(u, v_g, v_b, alpha) - v_g).pow(2).sum(-1)
    if variant == "p4":
        x = regularised64(s, g, b, alpha)
        return 1 - 0.5 * (unit64(f_image(x)) - unit64(f_text(g))).pow(2).sum(-1)
    if variant == "d5":
        position = unit64(regularised64(s, g, b, alpha))
        return csim64(f_image(torch.cat([position, unit64(s - s_prev)], -1)), f_text(g - b))
    raise AssertionError(variant)


def expected_scores(variant, heads, successful, failed, g, b, k, alpha) -> tuple[dict, dict]:
    def rewards(states, previous):
        with torch.no_grad():
            return thesis_reward(variant, heads, states, previous, g, b, alpha)

    def embeddings(episode):
        return torch.cat([episode["embedding"][:1], episode["next", "embedding"]]).double()

    def back(states, t, steps):
        return states[(t + steps).clamp(max=len(states) - 1)]

    positive, correlations, forward, backward = [], [], [], []
    for episode in successful:
        length = int(episode["next", "success"].reshape(-1).nonzero()[0]) + 1
        states = embeddings(episode)[:length + 1]
        t = torch.arange(len(states))
        values = rewards(states, states[(t - k).clamp(min=0)])
        positive.append(values[1:])
        correlations.append(rank_correlation_with_time(values[1:]))
        forward.append(values[1:length])
        backward.append(rewards(states, back(states, t, k))[1:length])
    negative = []
    for episode in failed:
        states = embeddings(episode)
        t = torch.arange(len(states))
        negative.append(rewards(states, states[(t - k).clamp(min=0)])[1:])
    positive, negative = torch.cat(positive), torch.cat(negative)
    scores = {"auroc": pair_auroc(positive, negative)}
    # The recipe computes in float32: a pair closer than float32 resolves may be ordered either
    # way there, so each score may move by the share of such pairs, and by nothing else.
    tolerance = {"auroc": near_tie_share(positive[:, None], negative[None, :])}
    if variant.startswith("d"):
        f, r = torch.cat(forward), torch.cat(backward)
        scores["direction_accuracy"] = float((f > r).double().mean()
                                             + 0.5 * (f == r).double().mean())
        tolerance["direction_accuracy"] = near_tie_share(f, r)
    else:
        scores["value_order_correlation"] = float(torch.tensor(correlations).mean())
        tolerance["value_order_correlation"] = 0.0
    return scores, tolerance


def near_tie_share(a: torch.Tensor, b: torch.Tensor) -> float:
    """The share of pairs (a_i, b_j) within 1e-6 of each other (a float32 score's resolution
    near 1)."""
    return float(((a - b).abs() < 1e-6).double().mean())


def test_recipe_scores_every_variant_end_to_end(tmp_path, my_reward_module):
    """Every variant is scored before and after finetuning; the zero-shot liv row and the
    untrained p3, p4 and d5 rows (with a non-default reward.alpha, which only they read) equal
    the scores written out from the thesis equations; finetuning moves every row with heads."""
    alpha = 0.7
    overrides = [f"reward.modules=[{my_reward_module}]",
                 "reward.positional=[liv,furl,p1,p2,p3,p4,rq_p5]", f"reward.alpha={alpha}"]
    cfg = config(tmp_path, *overrides)
    result, = evaluate_rewards.evaluate(cfg)
    output = tmp_path / "out" / "button-press-topdown"
    saved = json.loads((output / "results.json").read_text())
    rows = {(row["variant"], row["heads"]): row for row in saved["rows"]}
    variants = ["furl", "p1", "p2", "p3", "p4", "rq_p5", "d1", "d2", "d3", "d4", "d5"]
    assert set(rows) == {("liv", "zero-shot")} | {(variant, heads) for variant in variants
                                                  for heads in ("untrained", "finetuned")}
    # The held-out episodes the recipe scored on, and its goal and baseline texts.
    encoder = load_encoder("state", dim=16)
    data = prepare_task(task_config(cfg, cfg.env.task), encoder)
    assert len(data.successful) == 1 and len(data.failed) == 2
    for variant, heads_state in [("liv", "zero-shot"), ("p3", "untrained"),
                                 ("p4", "untrained"), ("d5", "untrained")]:
        torch.manual_seed(cfg.env.seed)  # the recipe's initial heads of every variant
        part = "directional" if variant.startswith("d") else "positional"
        fresh = TemporalReward(encoder.dim, data.goal_embedding, data.baseline_embedding,
                               **{"positional": None, "directional": None, part: variant})
        heads = getattr(fresh, f"{part}_heads")
        expected, tolerance = expected_scores(variant, heads, data.successful, data.failed,
                                   data.goal_embedding, data.baseline_embedding, cfg.reward.k,
                                   alpha)
        row = rows[variant, heads_state]
        for key, value in expected.items():
            assert row[key] == pytest.approx(value, abs=1e-6 + tolerance[key]), (variant, key)
    for variant in variants:
        untrained, finetuned = rows[variant, "untrained"], rows[variant, "finetuned"]
        metric = "direction_accuracy" if variant.startswith("d") else "value_order_correlation"
        assert (finetuned["auroc"], finetuned[metric]) != (untrained["auroc"], untrained[metric]), \
            variant
        assert untrained["direction_accuracy" if metric != "direction_accuracy"
                         else "value_order_correlation"] is None
    assert set(rows["d3", "finetuned"]["final_losses"]) == {"loss_directional"}
    assert saved["finetuning"]["updates"] == 10 and saved["finetuning"]["alpha"] == alpha
    assert saved["dataset"]["held_out"]["expert"]["episodes"] == 1
    assert "| rq_p5 | finetuned |" in (output / "results.md").read_text()
    assert sorted(p.stem for p in (output / "figures").glob("*.png")) == sorted(
        ["liv", *variants])
    # A second run reads the cached dataset and gives the same scores.
    again, = evaluate_rewards.evaluate(config(tmp_path, "figures=false", *overrides))
    assert again["dataset"]["source"].endswith(".pt")
    assert [row["auroc"] for row in again["rows"]] == [row["auroc"] for row in result["rows"]]


def test_recipe_writes_a_summary_for_several_tasks(tmp_path):
    cfg = config(tmp_path, "env.task=[button-press-topdown,window-close]",
                 "reward.positional=[liv,furl]", "reward.directional=[d3,d_certainty,d_sequence]",
                 "+reward.options.window=4", "figures=false")
    results = evaluate_rewards.evaluate(cfg)
    assert [result["task"] for result in results] == ["button-press-topdown", "window-close"]
    summary = (tmp_path / "out" / "summary.md").read_text()
    assert "| d3 |" in summary and "| d_sequence |" in summary and "window-close" in summary
    losses = {row["variant"]: set(row["final_losses"]) for row in results[0]["rows"]
              if row["heads"] == "finetuned"}
    # Each variant is trained with its registered objective, as in the training recipe.
    assert losses == {"furl": {"loss_positional"}, "d3": {"loss_directional"},
                      "d_certainty": {"loss_certainty"}, "d_sequence": {"loss_directional"}}


@pytest.mark.parametrize(("override", "key"), [
    ("env.task=drawer-opn", "env.task"),
    ("reward.positional=[furl,p9]", "reward.positional"),
    ("reward.directional=d7", "reward.directional"),
    ("finetune.stage=3", "finetune.stage"),
    ("dataset.held_out_fraction=1.5", "dataset.held_out_fraction"),
    ("dataset.expert_episodes=1", "dataset.expert_episodes"),
    ("dataset.failed_expert_episodes=1 dataset.random_episodes=1", "dataset.random_episodes"),
    ("encoder.device=gpu", "encoder.device"),
    ("env.task=reach reward.baseline=tailored", "reward.baseline"),
])
def test_bad_config_stops_before_any_work(tmp_path, override, key):
    with pytest.raises(ValueError, match=f"config {key}[=:]"):
        evaluate_rewards.evaluate(config(tmp_path, *override.split()))
    assert not (tmp_path / "cache").exists()
