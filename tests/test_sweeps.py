"""Sweeps on Hydra's launchers: studies compose, submitit resolves without Slurm, and the example
two-job joblib sweep writes one run per job, resumes when re-launched, and shares the cores."""

import json
import os
import subprocess
import sys

import pytest
from helpers import EXAMPLES, QUICK, RECIPES, make_checkpoint
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from temporal_torchrl.runs import threads_per_job

STUDIES = {  # study: (presets, protocol, runs)
    "table_5_2": ("furl,p2,p3,d3", "stage1", 96),
    "table_5_4": ("sac,furl,p1,p2,p3,p4", "stage2", 144),
    "table_5_6": ("furl,furl_rho025,furl_rho1,furl_rho2,furl_rho4", "stage2", 120),
    "table_5_8": ("sac,furl_rho1,d3_lambda30,d3,d3_lambda150", "stage2", 120),
    "table_5_12": ("sac,furl_rho1,d3_only,best_rho005,best,best_rho2", "stage2", 144),
}


def hydra_config(*overrides):
    with initialize_config_dir(config_dir=str(RECIPES), version_base=None):
        return compose("config", overrides=list(overrides), return_hydra_config=True)


@pytest.mark.parametrize("study", sorted(STUDIES))
def test_study_lists_its_table(study):
    presets, protocol, runs = STUDIES[study]
    params = hydra_config(f"+study={study}").hydra.sweeper.params
    assert params["preset"] == presets and params["protocol"] == protocol
    assert params["env.task"].split(",") == ["drawer-open", "door-open", "window-open",
                                            "window-close", "push", "button-press-topdown"]
    assert len(presets.split(",")) * 6 * len(params["env.seed"].split(",")) == runs


def test_study_presets_are_the_thesis_configurations():
    def reward(preset):
        cfg = hydra_config(f"preset={preset}").reward
        return cfg.positional, cfg.directional, cfg.rho, cfg.lambda_, cfg.baseline

    assert reward("d3_lambda30") == ("furl", "d3", 0.05, 30.0, "tailored")
    assert reward("d3_only") == ("none", "d3", 1.0, 4.0, "generic")
    assert reward("best_rho005") == ("furl", "d3", 0.05, 80.0, "generic")
    assert reward("best_rho2") == ("furl", "d3", 2.0, 2.0, "generic")
    assert reward("furl_rho025")[:3] == ("furl", "none", 0.25)


def test_submitit_slurm_launcher_resolves_without_slurm():
    cfg = hydra_config("+study=table_5_12", "hydra/launcher=submitit_slurm",
                       "hydra.launcher.partition=gpu", "hydra.launcher.gpus_per_node=1",
                       "hydra.launcher.timeout_min=480", "hydra.launcher.array_parallelism=24")
    launcher = OmegaConf.to_container(cfg.hydra.launcher, resolve=False)
    assert launcher["_target_"] == (
        "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher")
    assert (launcher["partition"], launcher["gpus_per_node"], launcher["timeout_min"],
            launcher["array_parallelism"]) == ("gpu", 1, 480, 24)
    assert cfg.hydra.sweep.dir == "sweeps/table_5_12"


def test_joblib_jobs_share_the_cores():
    cores = os.cpu_count()
    assert threads_per_job(OmegaConf.create({"n_jobs": -1})) == 1
    assert threads_per_job(OmegaConf.create({"n_jobs": 1})) == cores
    assert threads_per_job(OmegaConf.create({"n_jobs": 2 * cores})) == 1
    assert threads_per_job(OmegaConf.create({"partition": "gpu"})) is None


def test_a_finished_run_returns_its_summary_untouched(tmp_path, capsys):
    import sac_temporal
    from helpers import config

    summary = sac_temporal.train(config(tmp_path, "train.episodes=2"))
    path = tmp_path / "run" / "summary.json"
    written = path.stat().st_mtime_ns
    assert sac_temporal.train(config(tmp_path, "train.episodes=2", "resume=true")) == summary
    assert path.stat().st_mtime_ns == written
    assert "already complete (2 episodes)" in capsys.readouterr().out


@pytest.mark.slow
def test_the_example_sweep_runs_and_reports(tmp_path):
    """examples/sweep_and_report.sh (a two-job joblib sweep, then its report) writes one run per
    job and reports both seeds as one configuration. (A relaunch resuming a sweep's runs:
    test_sweep_failures.py.)"""
    sweep, out = tmp_path / "sweep", tmp_path / "report"
    result = subprocess.run(
        ["bash", str(EXAMPLES / "sweep_and_report.sh"), "hydra.launcher.n_jobs=2", *QUICK,
         "logger.backend=csv", "train.episodes=2"],
        env={**os.environ, "PYTHON": sys.executable, "SWEEP": str(sweep), "OUT": str(out)},
        capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    runs = sorted(path.parent for path in sweep.rglob("config.json"))
    assert [run.relative_to(sweep).as_posix() for run in runs] == [
        f"drawer-open/state_furl+d3_rho1_lambda4_generic_stage1/seed{seed}" for seed in (0, 1)]
    for run in runs:
        config = json.loads((run / "config.json").read_text())
        assert config["train"]["threads"] == max(1, os.cpu_count() // 2)
        assert json.loads((run / "summary.json").read_text())["episodes"] == 2
        rows = (run / "episodes.csv").read_text().splitlines()
        assert [row.split(",")[0] for row in rows[1:]] == ["1", "2"]
    # Both seeds grouped into one configuration, with censored TTFS (2 episodes).
    ttfs = (out / "ttfs.md").read_text()
    assert "drawer-open" in ttfs and ("2 censored" in ttfs or "(n=2)" in ttfs), ttfs
    assert (out / "report.md").is_file()
    assert (out / "success_curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_sweep_with_a_key_nothing_reads_stops_before_any_job(tmp_path):
    sweep = tmp_path / "sweep"
    result = subprocess.run(
        [sys.executable, str(RECIPES / "sac_temporal.py"), "-m", f"hydra.sweep.dir={sweep}",
         *QUICK, "env.seed=0,1", "+train.epsiodes=3"],
        capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode != 0
    assert "config key 'train.epsiodes' is not declared" in result.stderr
    assert "sweep job" not in result.stderr and not list(sweep.rglob("config.json"))


@pytest.mark.slow
def test_a_sweep_over_a_reward_option_makes_a_run_per_value(tmp_path):
    """``-m +reward.options.sharpness=2,4`` with the extending guide's d_sharp: the two jobs
    differ only in the option, whose digest names their directories, so both run (before, the
    second found the first's run and stopped with a RunConflictError)."""
    from temporal_torchrl.runs.naming import options_digest

    sweep = tmp_path / "sweep"
    result = subprocess.run(
        [sys.executable, str(RECIPES / "sac_temporal.py"), "-m", f"hydra.sweep.dir={sweep}",
         *QUICK, "train.episodes=1", "train.threads=1",
         f"reward.modules=[{EXAMPLES / 'my_directional_reward.py'}]",
         "reward.directional=d_sharp", "+reward.options.sharpness=2,4"],
        capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    runs = sorted(path.parent for path in sweep.rglob("config.json"))
    method = "drawer-open/state_furl+d_sharp_rho1_lambda4_generic"
    expected = {f"{method}_opt{options_digest({'sharpness': value})}_stage1/seed0": value
                for value in (2, 4)}
    assert sorted(run.relative_to(sweep).as_posix() for run in runs) == sorted(expected)
    for run in runs:
        config = json.loads((run / "config.json").read_text())
        assert config["reward"]["options"] == {
            "sharpness": expected[run.relative_to(sweep).as_posix()]}
        assert json.loads((run / "summary.json").read_text())["episodes"] == 1


def test_a_sweep_job_resumes_restarts_or_leaves_alone_what_it_finds(tmp_path, capsys):
    from temporal_torchrl.runs import RunDirectory, run_directory, sweep_job_config

    cfg = hydra_config(f"hydra.sweep.dir={tmp_path}", "encoder.name=state")
    fresh = sweep_job_config(cfg, cfg.hydra)
    run = RunDirectory(run_directory(fresh))
    assert run.path.is_relative_to(tmp_path) and not (fresh.resume or fresh.overwrite)
    run.create(config={})  # killed before its first checkpoint: started over, saying so
    restarted = sweep_job_config(cfg, cfg.hydra)
    assert restarted.overwrite and not restarted.resume
    assert f"{run.path}: no checkpoint yet, starting it over" in capsys.readouterr().out
    run.save_checkpoint(make_checkpoint(episode=1))
    resumed = sweep_job_config(cfg, cfg.hydra)
    assert resumed.resume and not resumed.overwrite
    with run.lock():  # a live job writes it: nothing decided here, train() stops on the lock
        left = sweep_job_config(cfg, cfg.hydra)
    assert not (left.resume or left.overwrite) and capsys.readouterr().out == ""


@pytest.mark.parametrize(("study", "presets", "tasks"), [
    ("sac_column", "sac", {"window-close": 200, "window-open": 200, "drawer-open": 300}),
    ("window_close_cpu_study", "sac,furl_rho1,none", {"window-close": 200}),
    ("table_5_12_cpu", "sac,furl_rho1,none",
     {"window-close": 200, "window-open": 200, "drawer-open": 300, "door-open": 400,
      "button-press-topdown": 400, "push": 1000})])
def test_budget_studies_run_each_task_to_its_ras_budget(study, presets, tasks):
    params = hydra_config(f"+study={study}").hydra.sweeper.params
    assert params["preset"] == presets and params["env.seed"] == "0,1,2,3"
    assert params["env.task"].split(",") == list(tasks)
    for task, budget in tasks.items():  # thesis Table 5.1's e, from the task registry
        for preset in presets.split(","):
            cfg = hydra_config(f"+study={study}", f"preset={preset}", "protocol=stage2",
                               f"env.task={task}")
            assert (cfg.train.episodes, cfg.train.random_steps) == (budget, 10_000)
            assert cfg.train.preload_positives == 50 and cfg.compile.enabled
    vlm = hydra_config("+study=window_close_cpu_study", "preset=none", "env.task=window-close")
    assert (vlm.encoder.name, vlm.env.image_size) == ("metaworld_small", 64)
    assert (vlm.reward.positional, vlm.reward.directional, vlm.reward.rho,
            vlm.reward.lambda_, vlm.reward.baseline) == ("furl", "d3", 1.0, 4.0, "generic")


@pytest.mark.parametrize("preset", ["sac", "furl_rho1", "none"])
@pytest.mark.parametrize("task", ["window-open", "drawer-open", "door-open"])
def test_table_5_12_cpu_runs_window_close_studys_configs_on_its_tasks(preset, task):
    # Its window-open and drawer-open cells were launched as window_close_cpu_study with
    # env.task overridden: the same configs, so the same run directories.
    overrides = (f"preset={preset}", "protocol=stage2", f"env.task={task}", "env.seed=1")

    def run_config(study):  # what the run's config.json holds: the config without hydra's
        cfg = OmegaConf.to_container(hydra_config(f"+study={study}", *overrides))
        return {key: value for key, value in cfg.items() if key != "hydra"}

    assert run_config("table_5_12_cpu") == run_config("window_close_cpu_study")


def test_a_task_without_a_ras_budget_is_named():
    cfg = hydra_config("+study=sac_column", "env.task=reach-wall")
    with pytest.raises(ValueError, match="task 'reach-wall' has no RAS budget"):
        _ = cfg.train.episodes
