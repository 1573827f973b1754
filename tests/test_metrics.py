"""TTFS, TT50S, RAS and episode success against hand-made success sequences."""

import pytest
import torch

from temporal_torchrl.protocol_metrics import episode_success, ras, time_to_successes, tt50s, ttfs


def test_ttfs_is_one_based_and_capped():
    assert ttfs([True]) == 1
    assert ttfs([False, False, True, True]) == 3
    assert ttfs(torch.tensor([0, 0, 0, 0, 1])) == 5
    assert ttfs([False] * 10) == 1000  # never: the horizon
    assert ttfs([False] * 1200) == 1000
    assert ttfs([False] * 1000 + [True]) == 1000  # success after the horizon does not count
    assert ttfs([False] * 999 + [True]) == 1000
    assert ttfs([False] * 5 + [True], horizon=4) == 4


def test_tt50s_counts_the_fiftieth_success():
    sequence = [False, True] * 60  # successes at episodes 2, 4, ..., the 50th at episode 100
    assert tt50s(sequence) == 100
    assert tt50s([True] * 49) == 1000
    assert tt50s([True] * 49 + [False] * 951 + [True]) == 1000
    assert tt50s([True] * 50) == 50
    assert time_to_successes([True, False, True], count=2) == 3


def test_ras_window_and_budget():
    assert ras([True] * 200, budget=200) == 1.0
    assert ras([True] * 50 + [False] * 150, budget=200) == 0.0
    sequence = [False] * 100 + [True] * 75 + [False] * 25 + [True] * 100
    # episodes 51..200: 50 failures, 75 successes, 25 failures -> 75 / 150
    assert ras(sequence, budget=200) == pytest.approx(0.5)
    assert ras(sequence, budget=200, window=25) == 0.0
    assert ras([True] * 3, budget=4, window=2) is None  # run too short: undefined
    with pytest.raises(ValueError, match="budget"):
        ras([True] * 10, budget=5, window=10)


def test_episode_success_any_step():
    assert episode_success(torch.tensor([[False], [True], [False]]))
    assert not episode_success(torch.zeros(5, 1, dtype=torch.bool))
    assert episode_success([0, 0, 1])


def test_bad_count_is_rejected():
    with pytest.raises(ValueError, match="count"):
        time_to_successes([True], count=0)
