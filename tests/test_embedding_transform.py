"""EmbeddingTransform: env path (reset and step), batched envs, replay-buffer path, specs."""

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.data.replay_buffers import SamplerWithoutReplacement
from torchrl.envs import SerialEnv, TransformedEnv
from torchrl.envs.utils import check_env_specs

from temporal_torchrl.encoders import Encoder, load_encoder, save_random_liv_checkpoint
from temporal_torchrl.envs import make_env
from temporal_torchrl.transforms import EmbeddingTransform

TASK = "drawer-open"


class MeanColourEncoder(Encoder):
    """A cheap image encoder (mean colour per frame) that records its batch sizes."""

    name = "mean_colour"
    input_key = "pixels"

    def __init__(self) -> None:
        super().__init__()
        self.dim = 3
        self.register_buffer("scale", torch.tensor([1.0, 2.0, 3.0]))
        self.batch_sizes: list[int] = []

    def embed_images(self, frames: torch.Tensor) -> torch.Tensor:
        self.batch_sizes.append(frames.shape[0])
        return frames.float().mean(dim=(1, 2)) * self.scale

    def _encode_text(self, texts: list[str]) -> torch.Tensor:
        return torch.zeros(len(texts), self.dim)


def _rendering_env(image_size: int = 32) -> TransformedEnv:
    return make_env(TASK, seed=0, render=True, image_size=image_size, max_episode_steps=5)


@pytest.fixture(scope="module")
def liv(tmp_path_factory):
    path = tmp_path_factory.mktemp("liv") / "model.pt"
    save_random_liv_checkpoint(path, seed=2)
    return load_encoder("liv", checkpoint=path)


def test_state_encoder_in_a_render_free_env():
    encoder = load_encoder("state", dim=16)
    env = make_env(TASK, seed=0, max_episode_steps=5)
    env = env.append_transform(EmbeddingTransform(encoder))
    check_env_specs(env)
    assert env.observation_spec["embedding"].shape == (16,)
    rollout = env.rollout(3)
    assert rollout["embedding"].shape == (3, 16)
    # The state encoder keeps "observation": the policy still reads it.
    torch.testing.assert_close(rollout["next", "embedding"],
                               encoder.embed(rollout["next", "observation"]))
    torch.testing.assert_close(rollout["embedding"], encoder.embed(rollout["observation"]))


def test_rendering_env_specs_and_pixels_dropped():
    encoder = MeanColourEncoder()
    env = _rendering_env()
    env = env.append_transform(EmbeddingTransform(encoder))
    check_env_specs(env)
    assert "pixels" not in env.observation_spec.keys()
    assert env.observation_spec["embedding"].dtype == torch.float32
    rollout = env.rollout(2)
    assert "pixels" not in rollout.keys(True, True)
    assert ("next", "pixels") not in rollout.keys(True, True)
    assert rollout["embedding"].shape == (2, 3)
    assert (rollout["embedding"] > 0).all()


def test_batched_env_runs_one_forward_per_batch():
    encoder = MeanColourEncoder()
    env = TransformedEnv(SerialEnv(2, _rendering_env),
                         EmbeddingTransform(encoder, del_in_key=False))
    rollout = env.rollout(2)
    assert encoder.batch_sizes == [2, 2, 2]  # reset, step, step
    assert rollout["embedding"].shape == (2, 2, 3)
    expected = rollout["next", "pixels"].float().mean(dim=(-3, -2)) * encoder.scale
    torch.testing.assert_close(rollout["next", "embedding"], expected)


def test_replay_path_embeds_both_keys_in_one_forward_and_allows_gradients():
    encoder = load_encoder("state", dim=8)
    transform = EmbeddingTransform(encoder)
    data = TensorDict({"observation": torch.randn(4, 39),
                       "next": {"observation": torch.randn(4, 39)}}, batch_size=[4])
    out = transform(data.clone())
    torch.testing.assert_close(out["next", "embedding"], encoder.embed(data["next", "observation"]))
    assert not out["embedding"].is_inference()
    head = torch.nn.Linear(8, 1)
    head(out["embedding"]).sum().backward()
    assert head.weight.grad is not None

    pixel_encoder = MeanColourEncoder()
    frames = TensorDict({"pixels": torch.randint(0, 256, (3, 2, 8, 8, 3), dtype=torch.uint8),
                         "next": {"pixels": torch.randint(0, 256, (3, 2, 8, 8, 3),
                                                          dtype=torch.uint8)}},
                        batch_size=[3, 2])
    embedded = EmbeddingTransform(pixel_encoder)(frames)
    assert pixel_encoder.batch_sizes == [12]
    assert embedded["next", "embedding"].shape == (3, 2, 3)
    assert "pixels" not in embedded.keys() and ("next", "pixels") not in embedded.keys(True)
    with pytest.raises(KeyError, match="neither 'pixels' nor \\('next', 'pixels'\\)"):
        EmbeddingTransform(pixel_encoder)(TensorDict({}, batch_size=[]))


def test_autocast_and_argument_checks():
    encoder = load_encoder("state", dim=8)
    observations = TensorDict({"observation": torch.randn(5, 39)}, batch_size=[5])
    out = EmbeddingTransform(encoder, autocast_dtype=torch.bfloat16)(observations.clone())
    assert out["embedding"].dtype == torch.float32
    torch.testing.assert_close(out["embedding"], encoder.embed(observations["observation"]),
                               rtol=2e-2, atol=2e-2)
    with pytest.raises(ValueError, match="autocast_dtype"):
        EmbeddingTransform(encoder, autocast_dtype=torch.int8)
    with pytest.raises(ValueError, match="load_encoder"):
        EmbeddingTransform(torch.nn.Linear(39, 8))
    transform = EmbeddingTransform(encoder)
    transform.train()
    assert not encoder.training
    env = make_env(TASK, seed=0, max_episode_steps=5)
    with pytest.raises(KeyError, match="render frames first"):
        env.append_transform(EmbeddingTransform(MeanColourEncoder())).observation_spec  # noqa: B018


@pytest.mark.slow
def test_liv_env_rollout_and_replay_buffer_give_the_same_embeddings(liv):
    env = _rendering_env(image_size=64)
    env = env.append_transform(EmbeddingTransform(liv, del_in_key=False))
    # check_env_specs on a rendering env is covered above with a cheap encoder; RN50 forwards
    # are kept to the rollout's three here.
    assert env.observation_spec["embedding"].shape == (1024,)
    rollout = env.rollout(2)
    assert env.observation_spec.is_in(rollout[0].select(*env.observation_spec.keys()))
    rollout["step"] = torch.arange(2)
    buffer = ReplayBuffer(storage=LazyTensorStorage(4), sampler=SamplerWithoutReplacement(),
                          batch_size=2, transform=EmbeddingTransform(liv))
    buffer.extend(rollout.exclude("embedding", ("next", "embedding")))
    sample = buffer.sample()
    assert "pixels" not in sample.keys()
    expected = rollout[sample["step"]]
    torch.testing.assert_close(sample["embedding"], expected["embedding"], rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(sample["next", "embedding"], expected["next", "embedding"],
                               rtol=1e-4, atol=1e-4)
    assert not torch.allclose(sample["embedding"], sample["next", "embedding"])
