"""Training metrics between two log lines: means of update outputs, relabelled-reward
statistics, and where they are logged (the run's ``metrics.jsonl`` and a TorchRL logger)."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.record.loggers import Logger

from temporal_torchrl.runs import RunDirectory


class MetricWindow:
    """Means of the training metrics since the last :meth:`flush` (losses, alpha, entropy,
    reward statistics), kept as tensors so an update never waits on ``.item()``.

    >>> window = MetricWindow()
    >>> window.add("sac", TensorDict({"loss_actor": torch.tensor(1.0)}, []))
    >>> window.add("sac", TensorDict({"loss_actor": torch.tensor(3.0)}, []))
    >>> window.flush()
    {'sac/loss_actor': 2.0}
    """

    def __init__(self) -> None:
        self._values: dict[str, list[torch.Tensor]] = {}

    def add(self, prefix: str, values: TensorDictBase) -> None:
        for key, value in values.items():
            self._values.setdefault(f"{prefix}/{key}", []).append(value.detach().float())

    @property
    def pending(self) -> bool:
        """Whether anything was added since the last :meth:`flush`."""
        return bool(self._values)

    def flush(self) -> dict[str, float]:
        means = {key: torch.stack(values).mean().item() for key, values in self._values.items()}
        self._values.clear()
        return means


def reward_statistics(next_batch: TensorDictBase) -> TensorDict:
    """Mean and std of the relabelled r_P and r_D in a SAC batch (empty without a VLM reward)."""
    stats = {}
    for key, name in (("positional_reward", "r_P"), ("directional_reward", "r_D")):
        if key in next_batch.keys():
            std, mean = torch.std_mean(next_batch[key])
            stats[f"{name}_mean"], stats[f"{name}_std"] = mean, std
    return TensorDict(stats, [])


@dataclass(frozen=True)
class RunLogger:
    """Where a run's training metrics go: always its ``metrics.jsonl``
    (:meth:`RunDirectory.append_metrics`), which reports read whatever the backend, and the
    TorchRL logger ``logger.backend`` names (None for ``none``), a sink for whoever watches
    the run there."""

    run: RunDirectory
    backend: Logger | None = None


def log_metrics(logger: RunLogger, metrics: dict[str, float], step: int) -> None:
    """Log one point at env step ``step``: a line of the run's ``metrics.jsonl``, then each
    value to the TorchRL logger, if any."""
    logger.run.append_metrics(step, metrics)
    if logger.backend is not None:
        for key, value in metrics.items():
            logger.backend.log_scalar(key, value, step=step)
