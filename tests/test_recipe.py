"""End-to-end runs of recipes/sac_temporal.py: every reward variant, stage 2, metrics, run
directories, bad config (resume: test_resume.py)."""

import json
import sys
import time
import warnings
from pathlib import Path

import pytest
import sac_temporal
import torch
from helpers import RECIPES, config, error_chain
from helpers import episode_csv_rows as episode_rows
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException

import temporal_torchrl.training.episodes as episodes_module
from temporal_torchrl.runs import RunDirectory, default_run_dir
from temporal_torchrl.training import factories
from temporal_torchrl.training.timing import PHASES

VARIANTS = [("none", "none"), ("liv", "none"), ("furl", "none"), ("p1", "none"),
            ("p2", "none"), ("p3", "none"), ("p4", "none"), ("furl", "d1"), ("furl", "d2"),
            ("furl", "d3"), ("furl", "d4"), ("furl", "d5"), ("furl", "d_certainty"),
            ("furl", "d_sequence")]


# ---- every reward variant


@pytest.mark.parametrize(("positional", "directional"), VARIANTS)
def test_every_reward_variant_runs(tmp_path, positional, directional):
    cfg = config(tmp_path, f"reward.positional={positional}",
                 f"reward.directional={directional}", "reward.lambda_=4.0")
    summary = sac_temporal.train(cfg)
    run_dir = tmp_path / "run"
    rows = episode_rows(run_dir)
    assert [int(row["episode"]) for row in rows] == [1, 2, 3]
    assert [int(row["env_steps"]) for row in rows] == [20, 40, 60]
    # The return is the sum of sparse task rewards, success - 1, of the stored transitions.
    stored = [torch.load(path, weights_only=True) for path in sorted(
        (run_dir / "replay").iterdir())]
    successes = [episode["success"][1:].reshape(-1) for episode in stored]
    assert [float(row["return"]) for row in rows] == [
        float((success.float() - 1).sum()) for success in successes]
    if positional == directional == "none":
        assert all(float(row["mean_vlm_reward"]) == 0.0 for row in rows)
    else:
        assert any(float(row["mean_vlm_reward"]) != 0.0 for row in rows)
    saved = json.loads((run_dir / "summary.json").read_text())
    assert saved["episodes"] == 3 and saved["env_steps"] == 60
    first_success = next((i + 1 for i, success in enumerate(successes) if success.any()), 1000)
    assert saved["ttfs"] == summary["ttfs"] == first_success
    assert saved["ras"] == {"value": None, "budget": 300, "window": 150}
    assert saved["config"]["reward"]["positional"] == positional


# ---- stage 2: preloaded and saved positives


def test_stage_two_preloads_positive_experts(tmp_path):
    cfg = config(tmp_path, "protocol=stage2", "train.preload_positives=2", "train.episodes=2",
                 "reward.directional=d3")
    assert cfg.train.preload_positives == 2
    sac_temporal.train(cfg)
    run_dir = tmp_path / "run"
    assert [row["stage"] for row in episode_rows(run_dir)] == ["2", "2"]
    assert len(list((run_dir / "replay").iterdir())) == 4  # 2 experts + 2 episodes
    state = RunDirectory(run_dir).load_checkpoint()
    assert state.inserted == 4 and state.episode == 2


@pytest.mark.parametrize(("steps_after_success", "length"), [("5", None), ("null", 500)])
def test_preloaded_experts_are_cut_or_whole(tmp_path, steps_after_success, length):
    cfg = config(tmp_path, f"train.expert_steps_after_success={steps_after_success}")
    episode, = factories.make_expert_episodes(cfg, None, 1)
    first = int(episode["next", "success"].squeeze(-1).float().argmax())
    assert len(episode) == (first + 6 if length is None else length)


def test_sac_baseline_preloads_experts_without_an_encoder(tmp_path):
    cfg = config(tmp_path, "preset=sac", "protocol=stage2", "train.preload_positives=1",
                 "train.episodes=1", "env.max_episode_steps=20")
    assert (cfg.reward.positional, cfg.reward.directional) == ("none", "none")
    assert sac_temporal.train(cfg)["episodes"] == 1
    assert RunDirectory(tmp_path / "run").load_checkpoint().inserted == 2


def test_save_positives_writes_each_successful_episode_whole(tmp_path, monkeypatch):
    """Episodes 1 and 3 count as successes here (a random policy does not succeed in 20 steps):
    their stored rows, whole, are what positives/ receives."""
    outcomes = iter([True, False, True])
    monkeypatch.setattr(episodes_module, "episode_success", lambda success: next(outcomes))
    sac_temporal.train(config(tmp_path, "train.save_positives=true"))
    run = RunDirectory(tmp_path / "run")
    assert sorted(path.name for path in (run.path / "positives").iterdir()) == [
        "000001.pt", "000003.pt"]
    saved = list(run.positive_episodes(2))
    replayed = list(run.replay_episodes(3))
    assert all(len(rows) == 21 for rows in saved)
    assert (saved[0] == replayed[0]).all() and (saved[1] == replayed[2]).all()
    run.truncate_positives(2)  # a resume from episode 2's checkpoint re-runs episode 3
    assert run.saved_positive_count() == 1


def positives_source(tmp_path) -> Path:
    """A run directory holding 2 saved positives: the whole scripted-expert episodes a stage-2
    run preloaded, saved as a stage-1 run with train.save_positives=true saves its own."""
    sac_temporal.train(config(tmp_path / "experts", "protocol=stage2",
                              "train.preload_positives=2", "train.episodes=1"))
    experts = RunDirectory(tmp_path / "experts" / "run")
    source = RunDirectory(tmp_path / "source")
    source.create(config=experts.config())
    for episode, rows in enumerate(experts.replay_episodes(2), start=1):
        source.save_positive_episode(episode, rows)
    return source.path


def test_positives_from_another_run_are_preloaded(tmp_path):
    source = positives_source(tmp_path)
    cfg = config(tmp_path, "protocol=stage2", "train.preload_positives=2", "train.episodes=1",
                 f"train.positives_from={source}")
    sac_temporal.train(cfg)
    run = RunDirectory(tmp_path / "run")
    preloaded = list(run.replay_episodes(2))
    for given, stored in zip(RunDirectory(source).positive_episodes(2), preloaded, strict=True):
        assert len(stored) == 501 and (given == stored).all()
    # s_g from the stored rows is the state goal_image_embedding takes from the expert episode
    # (rounded to the rows' float16)
    expected = RunDirectory(tmp_path / "experts" / "run").load_checkpoint().goal_image
    torch.testing.assert_close(run.load_checkpoint().goal_image, expected.half().float())
    # SAC without a VLM reward takes the observations only
    sac = config(tmp_path / "sac", "preset=sac", "protocol=stage2", "train.preload_positives=1",
                 "train.episodes=1", "env.max_episode_steps=20", f"train.positives_from={source}")
    sac_temporal.train(sac)
    assert "embedding" not in next(RunDirectory(tmp_path / "sac" / "run").replay_episodes(1))


@pytest.mark.parametrize(("override", "message"), [
    ("train.preload_positives=3", "holds 2 saved positive episodes, fewer than"),
    ("env.seed=1", "env.seed=0, this run has env.seed=1"),
    ("env.task=door-open", "env.task='drawer-open', this run has env.task='door-open'"),
    ("encoder.options.dim=8", "encoder.options"),
])
def test_positives_from_a_mismatched_source_is_refused(tmp_path, override, message):
    source = positives_source(tmp_path)
    cfg = config(tmp_path, "protocol=stage2", "train.preload_positives=2", "train.episodes=1",
                 f"train.positives_from={source}", *override.split())
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(".", r"\.")):
        sac_temporal.train(cfg)
    missing = config(tmp_path, "protocol=stage2", f"train.positives_from={tmp_path / 'none'}",
                     "overwrite=true")
    with pytest.raises(FileNotFoundError, match="no run directory there"):
        sac_temporal.train(missing)


USER_REWARD = """
from temporal_torchrl.rewards import cosine_similarity, register_reward


def towards_goal_since_start(heads, s, *, g, s0=None, **unused):
    return cosine_similarity(heads.image(s) - heads.image(s0), heads.text(g))


register_reward("user_p5", towards_goal_since_start, kind="positional")
"""


# ---- rewards of the user's and beyond the thesis


def test_a_reward_from_reward_modules_trains_and_resumes(tmp_path):
    from temporal_torchrl.rewards import POSITIONAL, unregister_reward

    module = tmp_path / "my_rewards.py"
    module.write_text(USER_REWARD)
    overrides = [f"reward.modules=[{module}]", "reward.positional=user_p5",
                 "reward.directional=none"]
    try:
        sac_temporal.train(config(tmp_path, *overrides, "train.stop_after_episodes=1"))
        assert "user_p5" in POSITIONAL
        # The saved config names the module, so a plain resume imports it (once) again.
        assert sac_temporal.train(config(tmp_path, "resume=true"))["episodes"] == 3
        assert float(episode_rows(tmp_path / "run")[-1]["mean_vlm_reward"]) != 0.0
    finally:
        unregister_reward("user_p5")
    with pytest.raises(ValueError, match="reward.modules"):
        sac_temporal.train(config(tmp_path, "reward.positional=user_p6"))
    with pytest.raises(FileNotFoundError, match="reward.modules"):
        sac_temporal.train(config(tmp_path, f"reward.modules=[{tmp_path / 'missing.py'}]"))


@pytest.mark.parametrize("overrides", [
    ("reward.directional=d_certainty",),
    ("reward.directional=d_sequence", "+reward.options.window=4"),
    ("reward.directional=d3", "reward.certainty_scaling=true"),
], ids=["d_certainty", "d_sequence", "d3_certainty_scaling"])
def test_beyond_thesis_rewards_train_and_resume_exactly(tmp_path, overrides):
    """d_certainty (its certainty loss), d_sequence (windows in the env and the buffer) and the
    certainty scaling train in stage 2, and a run stopped after an episode and resumed ends
    where the uninterrupted run does: heads, certainty references, optimizers, episodes."""
    common = [*overrides, "protocol=stage2", "train.preload_positives=1", "train.episodes=3"]
    straight = sac_temporal.train(config(tmp_path / "a", *common, "logger.backend=csv",
                                         "logger.log_every=10"))
    sac_temporal.train(config(tmp_path / "b", *common, "train.stop_after_episodes=2"))
    resumed = sac_temporal.train(config(tmp_path / "b", "resume=true"))
    assert resumed["successes"] == straight["successes"]
    first, second = (RunDirectory(tmp_path / name / "run").load_checkpoint()
                     for name in ("a", "b"))
    assert first.reward.keys() == second.reward.keys()
    for key, value in first.reward.items():
        torch.testing.assert_close(second.reward[key], value, msg=key)
    for saved, loaded in zip(first.trainer["optimizers"], second.trainer["optimizers"],
                             strict=True):
        for index, moments in saved["state"].items():
            torch.testing.assert_close(loaded["state"][index]["exp_avg"], moments["exp_avg"])
    assert episode_rows(tmp_path / "a" / "run") == episode_rows(tmp_path / "b" / "run")
    metrics = straight["last_metrics"]
    if "reward.directional=d_certainty" in overrides:
        # Its certainty loss ran, with targets of both signs (the experts are the positives).
        assert metrics["reward/loss_certainty"] > 0
        assert metrics["reward/target_positive"] > 0 > metrics["reward/target_negative"]
        assert "reward/loss_directional" not in metrics
    elif "reward.certainty_scaling=true" in overrides:
        assert first.reward["certainty.labels"].abs().sum() == 2 * 16  # a batch of each
        assert "xcertainty" in str(default_run_dir(config(tmp_path, *overrides)))
    else:
        assert first.reward["directional_heads.image.position_embedding"].shape == (3, 64)


# ---- metrics


def test_training_metrics_are_logged_and_summarised(tmp_path):
    """SAC's losses, alpha and entropy, the finetuning loss terms, the stage, the positives and
    the relabelled reward statistics reach the CSV logger every logger.log_every updates and
    summary.json; values checked against what the run stored."""
    cfg = config(tmp_path, "reward.directional=d3", "protocol=stage2",
                 "train.preload_positives=1", "train.episodes=2", "logger.backend=csv",
                 "logger.log_every=10")
    summary = sac_temporal.train(cfg)
    run_dir = tmp_path / "run"
    metrics = summary["last_metrics"]
    assert summary["updates"] == 30  # one per step after the 10 random ones (experts stored)
    expert = torch.load(run_dir / "replay" / "000000.pt", weights_only=True)
    assert metrics["train/positive_states"] == int((expert["label"] == 1).sum())
    assert metrics["train/stage"] == 2.0
    for key in ("sac/loss_actor", "sac/loss_qvalue", "sac/loss_alpha", "sac/alpha",
                "sac/entropy", "reward/loss_positional", "reward/loss_pos_neg",
                "reward/loss_pos_pos", "reward/loss_directional", "reward/loss_negative",
                "reward/loss_positive", "relabelled/r_P_mean", "relabelled/r_P_std",
                "relabelled/r_D_mean", "relabelled/r_D_std"):
        assert key in metrics, key
    # The positional loss is the sum of its stage-2 terms (means over the same updates).
    assert metrics["reward/loss_positional"] == pytest.approx(
        metrics["reward/loss_pos_neg"] + metrics["reward/loss_pos_pos"], rel=1e-5)
    assert metrics["relabelled/r_P_std"] > 0 and metrics["relabelled/r_D_std"] > 0  # per state
    # alpha = exp(log_alpha): lr 1e-4 over 30 updates keeps it within 1% of alpha_init = 1.
    assert metrics["sac/alpha"] == pytest.approx(1.0, abs=0.01)
    logged = next((run_dir / "logs").rglob("sac/alpha.csv")).read_text().splitlines()
    assert [int(line.split(",")[0]) for line in logged] == [20, 30, 40]  # env steps


def test_a_run_shorter_than_the_log_window_still_logs_its_metrics(tmp_path):
    """20 updates, logger.log_every 1000: the last (only) window is flushed when the run ends,
    into the logger at the last env step and into summary.json."""
    summary = sac_temporal.train(config(tmp_path, "train.episodes=2", "logger.backend=csv"))
    run_dir = tmp_path / "run"
    assert summary["updates"] == 20  # from the first stored episode on (step 21 to 40)
    metrics = summary["last_metrics"]
    assert json.loads((run_dir / "summary.json").read_text())["last_metrics"] == metrics
    for key in ("sac/loss_actor", "sac/loss_qvalue", "sac/alpha", "relabelled/r_P_mean",
                "relabelled/r_D_std", "train/stage"):
        assert key in metrics, key
    assert metrics["sac/alpha"] == pytest.approx(1.0, abs=0.01)  # 20 steps of lr 1e-4
    logged = next((run_dir / "logs").rglob("sac/alpha.csv")).read_text().splitlines()
    assert len(logged) == 1
    step, value = logged[0].split(",")
    assert int(step) == 40 and float(value) == pytest.approx(metrics["sac/alpha"])


def test_runs_report_where_their_time_goes(tmp_path):
    """Seconds per phase of the loop: a window with each logged metrics row (metrics.jsonl) and
    the run's totals in summary.json, every phase that ran, within the run's wall time."""
    start = time.perf_counter()
    summary = sac_temporal.train(config(tmp_path, "reward.directional=d3", "protocol=stage2",
                                        "train.preload_positives=1", "train.episodes=2",
                                        "logger.log_every=10", "eval.every=1",
                                        "eval.episodes=1"))
    wall = time.perf_counter() - start
    phases = summary["phase_seconds"]
    assert set(phases) == {f"{phase}" for phase in PHASES}  # each ran in this run
    assert all(seconds > 0 for seconds in phases.values())
    # nested: relabel is part of replay_sample; the rest do not overlap
    assert phases["relabel"] <= phases["replay_sample"]
    assert sum(seconds for phase, seconds in phases.items() if phase != "relabel") < wall
    rows = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").read_text()
            .splitlines()]
    windows = [row for row in rows if "time/sac_update" in row.get("metrics", row)]
    assert len(windows) == 3  # updates 10, 20, 30
    logged = sum(row.get("metrics", row)["time/sac_update"] for row in windows)
    assert logged == pytest.approx(phases["sac_update"], rel=1e-6)


# ---- run directories and the command line


def test_default_run_directories_differ_by_protocol_preset_and_seed():
    def run_dir(*overrides):
        with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
            return default_run_dir(compose("config", overrides=list(overrides)))

    runs = [("preset=best", "protocol=stage1"), ("preset=best", "protocol=stage2"),
            ("preset=furl", "protocol=stage2"), ("preset=furl_rho1", "protocol=stage2"),
            ("preset=d3", "protocol=stage2"), ("preset=d3", "protocol=stage2",
                                               "reward.baseline=generic"),
            ("preset=d3", "protocol=stage2", "reward.baseline=closed drawer"),
            ("preset=sac", "protocol=stage2"), ("preset=sac", "protocol=stage1"),
            ("preset=best", "protocol=stage2", "env.seed=1"), ("reward.lambda_=8",),
            ("reward.rho=0.5",), ()]
    directories = [run_dir(*overrides) for overrides in runs]
    assert len(set(directories)) == len(runs)
    assert directories[1] == Path(
        "runs/drawer-open/liv_furl+d3_rho1_lambda4_generic_stage2/seed0")
    assert directories[6].parent.name.endswith("_closed-drawer_stage2")
    assert directories[7] == Path("runs/drawer-open/sac_stage2/seed0")


def test_default_run_directories_tell_reward_options_apart():
    """A reward's options add ``_opt<8 hex>`` after the baseline (the SHA-256 of their sorted
    JSON), so configs that differ only in an option get their own directories; without options
    the name is exactly as before, so existing runs keep their directories and resume."""
    import hashlib

    from temporal_torchrl.runs.naming import options_digest

    def run_dir(*overrides):
        with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
            return default_run_dir(compose("config", overrides=list(overrides)))

    sharp = "reward.directional=d_sharp"
    assert run_dir() == Path(
        "runs/drawer-open/metaworld_small_furl+d3_rho1_lambda4_generic_stage1/seed0")
    assert run_dir(sharp) == Path(
        "runs/drawer-open/metaworld_small_furl+d_sharp_rho1_lambda4_generic_stage1/seed0")
    two, four = (run_dir(sharp, f"+reward.options.sharpness={value}") for value in (2, 4))
    assert options_digest({"sharpness": 2}) == "555184a7" == hashlib.sha256(
        b'{"sharpness":2}').hexdigest()[:8]
    assert two == Path("runs/drawer-open/metaworld_small_furl+d_sharp_rho1_lambda4_generic"
                       "_opt555184a7_stage1/seed0")
    assert four == Path(str(two).replace("555184a7", options_digest({"sharpness": 4})))
    assert four != two
    # One reward, one directory: the options' order and 2 for 2.0 change nothing.
    assert run_dir(sharp, "+reward.options.sharpness=2.0") == two
    assert options_digest({"sharpness": 2.0, "margin": 0.2}) == options_digest(
        {"margin": 0.2, "sharpness": 2})
    assert options_digest({"sharpness": 2.5}) != options_digest({"sharpness": 2})


def test_default_run_directories_of_the_built_in_options_keep_their_names():
    """d_sequence's window and d_certainty's certainty estimate are reward options now: a run
    of their defaults keeps the directory it had (no ``_opt``: only options set name it), and
    so does one given a deprecated key at its old default, which every saved run's config.json
    holds; a deprecated key set to another value names the directory its option does."""
    from temporal_torchrl.configs.rules import validate_recipe_config
    from temporal_torchrl.runs.naming import options_digest

    def run_dir(*overrides, deprecated: str | None = None):
        with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
            cfg = compose("config", overrides=list(overrides))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            validated = validate_recipe_config(cfg)
        assert [str(warning.message).split(" is deprecated")[0] for warning in caught
                if warning.category is FutureWarning] == ([deprecated] if deprecated else [])
        # Named from the composed config (a sweep job's) and from the validated one alike.
        assert default_run_dir(validated) == default_run_dir(cfg)
        return default_run_dir(cfg)

    before = "runs/drawer-open/metaworld_small_furl+{}_rho1_lambda4_generic{}_stage1/seed0"
    sequence, certainty = "reward.directional=d_sequence", "reward.directional=d_certainty"
    assert run_dir(sequence) == Path(before.format("d_sequence", "")) == run_dir(
        sequence, "reward.window=8")
    assert run_dir(certainty) == Path(before.format("d_certainty", "")) == run_dir(
        certainty, "reward.certainty_bandwidth=0.1", "reward.certainty_prior=1.0")
    twelve = Path(before.format("d_sequence", f"_opt{options_digest({'window': 12})}"))
    assert run_dir(sequence, "+reward.options.window=12") == twelve == run_dir(
        sequence, "reward.window=12", deprecated="config reward.window=12")


@pytest.mark.slow
def test_rendering_with_random_liv_checkpoint(tmp_path):
    """A new user's command with a local LIV checkpoint: the output is the recipe's own lines,
    true and in order, with no library line saying the model is random or INFO noise."""
    import subprocess

    from temporal_torchrl.encoders import save_random_liv_checkpoint

    checkpoint = tmp_path / "liv.pt"
    save_random_liv_checkpoint(checkpoint)
    run_dir = tmp_path / "run"
    process = subprocess.run(
        # LIV's zero-shot reward: no heads, so no expert episode to embed with RN50 for s_g.
        [sys.executable, str(RECIPES / "sac_temporal.py"), "encoder.name=liv",
         "reward.positional=liv", "reward.directional=none", "train.threads=1",
         f"encoder.checkpoint={checkpoint}", "env.image_size=64", "env.max_episode_steps=5",
         "train.episodes=2", "train.random_steps=3", "sac.batch_size=4", "reward.batch_size=4",
         f"output_dir={run_dir}", "logger.backend=none"],
        capture_output=True, text=True, timeout=600)
    assert process.returncode == 0, process.stderr[-2000:]
    output = process.stdout + process.stderr
    for noise in ("No pretrained weights", "initialized randomly", "INFO", "Parsing model"):
        assert noise not in output, noise
    lines = process.stdout.splitlines()
    assert lines[0] == f"run directory: {run_dir}"
    assert lines[1] == f"encoder: liv, 1024-d, weights: {checkpoint}"
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["encoder"] == "liv" and summary["env_steps"] == 10
    rows = episode_rows(run_dir)
    assert [int(row["env_steps"]) for row in rows] == [5, 10]


@pytest.mark.slow
def test_default_config_renders_and_uses_the_shipped_encoder(tmp_path, capsys):
    """The README's main command, shortened: the defaults need no network and no weights file."""
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        cfg = compose("config", overrides=[
            f"output_dir={tmp_path / 'run'}", "env.max_episode_steps=8", "train.episodes=2",
            "train.random_steps=4", "sac.batch_size=4", "reward.batch_size=4",
            "train.progress=false"])
    assert (cfg.encoder.name, cfg.encoder.checkpoint) == ("metaworld_small", None)
    assert (cfg.reward.positional, cfg.reward.directional) == ("furl", "d3")
    summary = sac_temporal.train(cfg)
    assert summary["encoder"] == "metaworld_small" and summary["env_steps"] == 16
    assert "encoder: metaworld_small, 256-d, weights: shipped with the package" in (
        capsys.readouterr().out)
    rows = episode_rows(tmp_path / "run")
    assert all(float(row["mean_vlm_reward"]) != 0.0 for row in rows)
    assert (tmp_path / "run" / "logs").exists()


# ---- configs refused or composed


@pytest.mark.parametrize(("override", "key"), [
    ("env.task=not-a-task", "env.task"), ("encoder.name=clip9", "encoder.name"),
    ("reward.positional=p9", "reward.positional"), ("reward.directional=d7", "reward.directional"),
    ("reward.window=1", "reward.window"), ("reward.certainty_prior=0", "reward.certainty_prior"),
    ("reward.certainty_bandwidth=-1", "reward.certainty_bandwidth"),
    ("reward.directional=d_sequence +reward.options.window=1", "reward.options.window=1"),
    ("reward.directional=d_certainty +reward.options.certainty_prior=0",
     "reward.options.certainty_prior=0"),
    ("+reward.options.window=4", "expected an option of furl or d3: they declare none"),
    ("reward.certainty_scaling=maybe", "reward.certainty_scaling"),
    ("reward.directional=none reward.certainty_scaling=true", "it scales r_D"),
    ("reward.rho=-0.1", "reward.rho"), ("reward.lambda_=-1", "reward.lambda_"),
    ("reward.k=0", "reward.k"), ("train.episodes=0", "train.episodes"),
    ("logger.backend=tensorboard", "logger.backend"),
    ("train.expert_steps_after_success=-1", "train.expert_steps_after_success"),
    ("train.relay=maybe", "train.relay"), ("train.relay_periods=[0]", "train.relay_periods"),
    ("train.relay_noise=-1", "train.relay_noise"),
    ("train.save_positives=always", "train.save_positives"),
    ("encoder=state", "not a subclass of EncoderConfig. value: state\n    full_key: encoder"),
    ("reward=furl", "not a subclass of RewardConfig. value: furl\n    full_key: reward"),
    ("sac.batch_size=0", "sac.batch_size"),
    ("train.utd_ratio=-1", "train.utd_ratio"), ("env.num_envs=0", "env.num_envs"),
    ("train.device=gpu", "train.device"), ("replay_buffer.device=tpu", "replay_buffer.device"),
    ("compile.enabled=maybe", "compile.enabled"), ("compile.mode=fastest", "compile.mode"),
    ("compile.cudagraphs=true train.device=cpu", "CUDA graphs need a CUDA train.device"),
    ("replay_buffer.capacity=10", "replay_buffer.capacity"),
    ("replay_buffer.embedding_dtype=float8", "replay_buffer.embedding_dtype"),
    ("sac.hidden_sizes=[]", "sac.hidden_sizes"), ("sac.gamma=1.5", "sac.gamma"),
    ("encoder.device=gpu", "encoder.device"),
    pytest.param("encoder.device=cuda", "no CUDA GPU", marks=pytest.mark.skipif(
        torch.cuda.is_available(), reason="needs a machine without CUDA")),
    ("env.task=reach reward.baseline=tailored", "reach has no tailored baseline"),
])
def test_bad_config_stops_before_any_work(tmp_path, override, key):
    """A wrong type stops Hydra as it composes (its error names the override, the OmegaConf
    error it wraps the key), a value out of range or against the rules the recipe."""
    with pytest.raises((ConfigCompositionException, ValueError)) as error:
        sac_temporal.train(config(tmp_path, *override.split()))
    assert key in error_chain(error.value)
    assert not (tmp_path / "run").exists()


def test_existing_run_needs_overwrite(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "episodes.csv").write_text("old")
    with pytest.raises(FileExistsError, match="overwrite=true"):
        sac_temporal.train(config(tmp_path, "train.episodes=1"))
    sac_temporal.train(config(tmp_path, "train.episodes=1", "overwrite=true"))
    assert len(episode_rows(tmp_path / "run")) == 1


def test_presets_compose(tmp_path):
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        best = compose("config", overrides=["preset=best", "protocol=stage2"])
    assert (best.reward.positional, best.reward.directional) == ("furl", "d3")
    assert (best.reward.rho, best.reward.lambda_, best.reward.baseline) == (1.0, 4.0, "generic")
    assert best.train.preload_positives == 50 and best.encoder.name == "liv"
    d5 = config(tmp_path, "preset=d5")
    assert (d5.reward.lambda_, d5.reward.rho, d5.train.preload_positives) == (80.0, 0.05, 0)
    assert config(tmp_path, "preset=furl_rho1").reward.rho == 1.0
