"""The CUDA path's device placement, checked on a machine without a GPU.

Under PyTorch's ``FakeTensorMode`` tensors can live on a fake ``cuda`` device with no GPU, and
an op that mixes a ``cuda`` and a ``cpu`` tensor raises ``FakeTensorDeviceMismatchError``: the
first-run GPU failure of a tensor created on the wrong device, found here instead. Checked: a
replay sample moved to the training device and relabelled there by the reward heads, and the
heads' finetuning losses on it.

What cannot be checked this way, tried on the 2-core CI machine (torch 2.14.1, torchrl 0.14.1):

- a backward pass: the autograd engine asks the CUDA driver for a context even for fake tensors
  (``hasPrimaryContext expects a valid device index``), so no optimizer step;
- the SAC agent as the recipe builds it: its MLPs' lazy layers cannot be created under the mode
  (an ``UninitializedParameter`` cannot become a fake tensor), and built outside then moved,
  the actor's distribution keeps the CPU bounds the recipe moves first;
- sampling itself: the sampler's data-dependent ops (``nonzero``) have no fake kernel, so a
  batch is drawn on the storage's CPU and then moved, as the buffer does.

Those run on a real GPU only (``tests/test_cuda.py``, ``benchmarks/gpu_check.sh``).
"""

import pytest
import torch
from helpers import D, insert
from tensordict import TensorDict
from torch._subclasses.fake_tensor import FakeTensorDeviceMismatchError, FakeTensorMode

from temporal_torchrl.data import EpisodeReplayBuffer
from temporal_torchrl.objectives import finetuning_losses
from temporal_torchrl.rewards import REWARD_KEYS, TemporalReward
from temporal_torchrl.transforms import TemporalRewardTransform

CUDA = torch.device("cuda", 0)  # with its index: tensordict asks the driver for the current one


def _filled_buffer() -> tuple[TemporalReward, EpisodeReplayBuffer]:
    reward = TemporalReward(D, torch.randn(D), torch.randn(D), directional="d3", k=2)
    buffer = EpisodeReplayBuffer(capacity=200, k=2, batch_size=16,
                                 finetuning_batch_size=16, permanent_episodes=1)
    insert(buffer, 0, 12, successes=(10, 11))
    for episode in range(1, 5):
        insert(buffer, episode, 12)
    return reward, buffer


@pytest.fixture
def on_fake_cuda():
    return FakeTensorMode(allow_non_fake_inputs=True)


def test_relabelling_and_the_head_losses_keep_every_tensor_on_the_training_device(
        on_fake_cuda):
    reward, buffer = _filled_buffer()
    batch, heads_batch = buffer.sample(), buffer.finetuning.sample()  # on the storage's CPU
    goal_image = torch.randn(D)
    with on_fake_cuda:
        reward = reward.to(CUDA)
        batch = TemporalRewardTransform(reward)(batch.to(CUDA))  # relabelled on the device
        assert {batch["next", key].device for key in REWARD_KEYS} == {CUDA}
        for head_loss in finetuning_losses(reward, goal_image.to(CUDA), stage=2):
            out = head_loss(heads_batch.to(CUDA))  # its heads are the reward's, moved
            assert out[head_loss.loss_key].device == CUDA


def test_a_tensor_left_on_the_cpu_fails_the_check(on_fake_cuda):
    # The check has teeth: one CPU tensor in the relabelling (a goal embedding not moved with
    # the heads) raises, as it would on a GPU.
    reward, buffer = _filled_buffer()
    batch = buffer.sample()
    with on_fake_cuda:
        reward = reward.to(CUDA)
        reward.goal_embedding = torch.randn(D)  # left behind on the CPU
        transform = TemporalRewardTransform(reward)
        with pytest.raises(FakeTensorDeviceMismatchError, match="at least two devices"):
            transform._call(TensorDict({key: batch["next", key].to(CUDA) for key in (
                "embedding", "initial_embedding", "previous_embedding", "success")},
                batch.batch_size, device=CUDA))
