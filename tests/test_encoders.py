"""Encoders: LIV's checkpoint format and loader, preprocessing, open_clip and state encoders."""

import os
import subprocess
import sys

import open_clip
import pytest
import torch
from tensordict import TensorDict

from temporal_torchrl.encoders import (
    ENCODERS,
    Encoder,
    ImagePreprocessor,
    LIVEncoder,
    OpenCLIPEncoder,
    StateEncoder,
    load_encoder,
    make_preprocessor,
    save_random_liv_checkpoint,
)
from temporal_torchrl.encoders.open_clip_encoder import PretrainedWeightsUnavailableError
from temporal_torchrl.encoders.preprocessing import CLIP_MEAN, CLIP_STD
from temporal_torchrl.transforms import EmbeddingTransform

PROMPTS = ["open the drawer", "robot arm beside table"]


@pytest.fixture(scope="module")
def liv_files(tmp_path_factory):
    """A random-weight checkpoint in LIV's on-disk format, its source model, and the encoder."""
    path = tmp_path_factory.mktemp("liv") / "model.pt"
    source = save_random_liv_checkpoint(path, seed=1)
    encoder = load_encoder("liv", checkpoint=path)
    return path, source, encoder


@pytest.fixture(scope="module")
def frames():
    generator = torch.Generator().manual_seed(0)
    return torch.randint(0, 256, (2, 48, 64, 3), dtype=torch.uint8, generator=generator)


def test_checkpoint_is_written_in_liv_format(liv_files):
    path, _, _ = liv_files
    checkpoint = torch.load(path, weights_only=True)
    weights = checkpoint["liv"]
    assert len(weights) == 489
    assert all(key.startswith("module.model.") for key in weights)
    assert weights["module.model.visual.conv1.weight"].dtype == torch.float16
    assert weights["module.model.visual.attnpool.q_proj.weight"].dtype == torch.float16
    assert weights["module.model.transformer.resblocks.0.attn.in_proj_weight"].dtype == (
        torch.float16)
    assert weights["module.model.text_projection"].dtype == torch.float16
    assert weights["module.model.visual.bn1.running_var"].dtype == torch.float32
    assert weights["module.model.token_embedding.weight"].dtype == torch.float32
    assert weights["module.model.ln_final.weight"].dtype == torch.float32


@pytest.mark.slow
def test_liv_reproduces_source_image_and_text_embeddings(liv_files, frames):
    _, source, encoder = liv_files
    assert isinstance(encoder, LIVEncoder) and encoder.dim == 1024
    images = encoder.preprocess_images(frames)
    with torch.no_grad():
        expected_images = source.encode_image(images)
        expected_text = source.encode_text(open_clip.get_tokenizer("RN50-quickgelu")(PROMPTS))
    embeddings = encoder.embed_images(frames)
    assert embeddings.shape == (2, 1024) and embeddings.dtype == torch.float32
    torch.testing.assert_close(embeddings, expected_images, rtol=1e-4, atol=1e-5)
    text = encoder.embed_text(PROMPTS)
    torch.testing.assert_close(text, expected_text, rtol=1e-4, atol=1e-5)
    # Not normalised (LIV compares with cosine similarity itself).
    assert not torch.allclose(text.norm(dim=-1), torch.ones(2))
    assert not torch.allclose(text[0], text[1])


@pytest.mark.slow
def test_liv_channels_last_and_bf16_autocast_keep_the_embeddings(liv_files, frames):
    """The GPU benchmark's configuration, run on the CPU: same embeddings, up to bf16 rounding."""
    path, _, encoder = liv_files
    frames = frames[:1]
    fast = LIVEncoder(path, channels_last=True)
    assert fast.preprocess_images(frames).is_contiguous(memory_format=torch.channels_last)
    reference = encoder.embed_images(frames)
    torch.testing.assert_close(fast.embed_images(frames), reference, rtol=1e-4, atol=1e-4)
    embedded = EmbeddingTransform(fast, autocast_dtype=torch.bfloat16)(
        TensorDict({"pixels": frames}, batch_size=[1]))
    assert embedded["embedding"].dtype == torch.float32
    cosine = torch.nn.functional.cosine_similarity(embedded["embedding"], reference)
    assert (cosine > 0.99).all(), cosine


def test_liv_is_frozen_float32_and_stays_in_eval(liv_files):
    _, _, encoder = liv_files
    assert all(not p.requires_grad for p in encoder.parameters())
    assert all(p.dtype == torch.float32 for p in encoder.parameters())
    encoder.train()
    assert not any(module.training for module in encoder.modules())


def test_text_embeddings_are_cached_per_prompt(liv_files, monkeypatch):
    _, _, encoder = liv_files
    first = encoder.embed_text(["pick up the puck"])
    calls = []
    original = encoder._encode_text
    monkeypatch.setattr(encoder, "_encode_text", lambda texts: calls.append(texts) or
                        original(texts))
    again = encoder.embed_text(["pick up the puck", "pick up the puck"])
    assert calls == []
    torch.testing.assert_close(again, first.expand(2, -1))
    encoder.embed_text(["pick up the puck", "push the button"])
    assert calls == [["push the button"]]
    with pytest.raises(ValueError, match="list of strings"):
        encoder.embed_text("a bare string")


@pytest.mark.slow
def test_bad_checkpoint_is_refused_by_name_and_nothing_is_half_loaded(liv_files, tmp_path):
    path, _, encoder = liv_files
    weights = torch.load(path, weights_only=True)["liv"]
    del weights["module.model.visual.layer4.2.bn3.running_mean"]
    weights["module.model.visual.extra_head.weight"] = torch.zeros(3)
    weights["module.model.text_projection"] = torch.zeros(512, 512, dtype=torch.float16)
    bad = tmp_path / "bad.pt"
    torch.save({"liv": weights}, bad)
    model = encoder.model
    conv = model.visual.conv1.weight.clone()
    with pytest.raises(ValueError) as error:
        encoder.load_checkpoint(bad)
    message = str(error.value)
    assert "missing keys: visual.layer4.2.bn3.running_mean" in message
    assert "unexpected keys: visual.extra_head.weight" in message
    assert "text_projection (checkpoint (512, 512), model (512, 1024))" in message
    assert encoder.checkpoint_path == path and encoder.model is model
    torch.testing.assert_close(model.visual.conv1.weight, conv, rtol=0, atol=0)


def test_files_that_are_not_liv_checkpoints_are_refused(tmp_path):
    plain = tmp_path / "plain.pt"
    torch.save({"state_dict": {"w": torch.zeros(1)}}, plain)
    with pytest.raises(ValueError, match="'liv' entry"):
        load_encoder("liv", checkpoint=plain)
    with pytest.raises(FileNotFoundError, match="not a file"):
        load_encoder("liv", checkpoint=tmp_path / "absent.pt")


@pytest.mark.slow
def test_hub_download_fails_cleanly_offline(tmp_path):
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path)}
    env.pop("HF_HUB_CACHE", None)
    code = (
        "from temporal_torchrl.encoders import load_encoder\n"
        "try:\n    load_encoder('liv')\n"
        "except FileNotFoundError as error:\n    print(error)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    message = result.stdout
    assert "'model.pt'" in message and "'jasonyma/LIV'" in message
    assert "checkpoint='/path/to/model.pt'" in message
    assert not list(tmp_path.rglob("*.pt"))


def _normalise(channels):
    mean = torch.tensor(CLIP_MEAN).view(3, 1, 1)
    std = torch.tensor(CLIP_STD).view(3, 1, 1)
    return (channels - mean) / std


def test_preprocessing_matches_a_hand_computation():
    frame = torch.arange(4 * 4 * 3, dtype=torch.uint8).view(1, 4, 4, 3) * 5
    image = frame[0].permute(2, 0, 1).float() / 255
    # Bilinear, no antialias, exact 2x downscale: each output pixel is the mean of a 2x2 block.
    blocks = image.unfold(1, 2, 2).unfold(2, 2, 2).mean(dim=(-1, -2))
    torch.testing.assert_close(ImagePreprocessor(2)(frame)[0], _normalise(blocks))

    wide = torch.arange(2 * 4 * 3, dtype=torch.uint8).view(1, 2, 4, 3)
    # Shorter side already 2: no resize; center crop keeps columns 1 and 2.
    expected = _normalise(wide[0, :, 1:3].permute(2, 0, 1).float() / 255)
    torch.testing.assert_close(ImagePreprocessor(2)(wide)[0], expected)
    bgr = ImagePreprocessor(2, channel_order="bgr")(wide)[0]
    expected_bgr = (wide[0, :, 1:3].flip(-1).permute(2, 0, 1).float() / 255
                    - torch.tensor(CLIP_MEAN).view(3, 1, 1)) / torch.tensor(CLIP_STD).view(3, 1, 1)
    torch.testing.assert_close(bgr, expected_bgr)


def test_preprocessing_shapes_presets_and_errors():
    frames = torch.randint(0, 256, (3, 100, 150, 3), dtype=torch.uint8)
    assert ImagePreprocessor()(frames).shape == (3, 3, 224, 224)
    rendered = torch.randint(0, 256, (1, 256, 256, 3), dtype=torch.uint8)
    prior = make_preprocessor("metaworld_prior")
    torch.testing.assert_close(prior(rendered),
                               ImagePreprocessor()(rendered[:, 32:224, 32:224].contiguous()))
    with pytest.raises(ValueError, match="256"):
        prior(frames)
    with pytest.raises(ValueError, match="uint8"):
        ImagePreprocessor()(frames.float())
    with pytest.raises(ValueError, match="unknown preprocessing 'jpeg'"):
        make_preprocessor("jpeg")


def test_state_encoder_is_seeded_and_render_free():
    encoder = load_encoder("state", dim=32)
    assert (encoder.name, encoder.dim, encoder.input_key) == ("state", 32, "observation")
    observations = torch.randn(5, 39)
    embeddings = encoder.embed(observations)
    assert embeddings.shape == (5, 32) and embeddings.dtype == torch.float32
    torch.testing.assert_close(embeddings, StateEncoder(dim=32).embed(observations))
    assert not torch.allclose(embeddings, StateEncoder(dim=32, seed=1).embed(observations))
    text = encoder.embed_text(PROMPTS)
    torch.testing.assert_close(text, StateEncoder(dim=32).embed_text(PROMPTS))
    assert not torch.allclose(text[0], text[1])
    assert StateEncoder().dim == 1024
    with pytest.raises(NotImplementedError, match="not images"):
        encoder.embed_images(torch.zeros(1, 8, 8, 3, dtype=torch.uint8))
    with pytest.raises(ValueError, match=r"\[N, 39\]"):
        encoder.embed(torch.zeros(5, 12))


def test_load_encoder_refuses_unknown_names():
    assert ENCODERS == ("liv", "open_clip", "state", "metaworld_small")
    with pytest.raises(ValueError, match="unknown encoder 'vip'.*'liv', 'open_clip', 'state', "
                                         "'metaworld_small'"):
        load_encoder("vip")
    with pytest.raises(ValueError, match="no weights"):
        load_encoder("state", checkpoint="model.pt")
    with pytest.raises(ValueError, match="unknown open_clip model 'ViT-Q-99'"):
        load_encoder("open_clip", model_name="ViT-Q-99")


@pytest.mark.slow
def test_open_clip_encoder_loads_a_local_file(liv_files, frames, tmp_path):
    _, source, _ = liv_files
    path = tmp_path / "rn50.pt"
    torch.save(source.state_dict(), path)
    encoder = load_encoder("open_clip", model_name="RN50-quickgelu", checkpoint=path,
                           preprocessing="liv")
    assert isinstance(encoder, OpenCLIPEncoder) and encoder.dim == 1024
    with torch.no_grad():
        expected = source.encode_image(encoder.preprocess_images(frames[:1]))
    torch.testing.assert_close(encoder.embed_images(frames[:1]), expected, rtol=1e-4, atol=1e-5)


def test_open_clip_checkpoint_of_another_architecture_is_refused_clearly(liv_files, tmp_path):
    liv_path, source, _ = liv_files
    path = tmp_path / "rn50.pt"
    torch.save(source.state_dict(), path)
    with pytest.raises(ValueError) as error:
        load_encoder("open_clip", checkpoint=path)  # model_name defaults to ViT-B-32
    message = str(error.value)
    assert len(message) < 3000 and isinstance(error.value.__cause__, RuntimeError)
    assert f"checkpoint {str(path)!r}" in message and "model_name='ViT-B-32'" in message
    assert "missing keys: visual.class_embedding" in message
    assert "unexpected keys: " in message and "visual.bn1.weight" in message
    assert "text_projection (checkpoint (512, 1024), model (512, 512))" in message
    assert "+encoder.options.model_name=RN50-quickgelu" in message
    with pytest.raises(ValueError, match=r"LIV's model.pt.*load_encoder\('liv'"):
        load_encoder("open_clip", checkpoint=liv_path)


def test_open_clip_pretrained_tag_fails_cleanly_offline(tmp_path, monkeypatch):
    import huggingface_hub.constants

    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)
    with pytest.raises(PretrainedWeightsUnavailableError) as error:
        OpenCLIPEncoder("RN50", pretrained="openai", cache_dir=str(tmp_path))
    assert isinstance(error.value, FileNotFoundError) and isinstance(error.value, RuntimeError)
    assert isinstance(error.value.__cause__, OSError)
    message = str(error.value)
    assert "weights 'openai' for 'RN50'" in message and "'timm/resnet50_clip.openai'" in message
    assert f"cache ({tmp_path})" in message and "seems offline" in message
    assert "checkpoint='/path/to/open_clip_pytorch_model.bin'" in message
    assert "encoder.checkpoint=/path/to/open_clip_pytorch_model.bin" in message
    assert not list(tmp_path.rglob("*.bin"))
    with pytest.raises(ValueError, match=r"unknown open_clip pretrained tag 'nonsense' for 'RN50'"
                                         r".*\['openai', 'yfcc15m', 'cc12m'\]"):
        OpenCLIPEncoder("RN50", pretrained="nonsense", cache_dir=str(tmp_path))


def test_open_clip_pretrained_tag_loads_from_the_cache_offline(liv_files, tmp_path, monkeypatch):
    import huggingface_hub.constants

    _, source, _ = liv_files  # RN50-quickgelu: the same weights as RN50's
    commit = "0" * 40
    snapshot = tmp_path / "models--timm--resnet50_clip.openai" / "snapshots" / commit
    snapshot.mkdir(parents=True)
    torch.save(source.state_dict(), snapshot / "open_clip_pytorch_model.bin")
    (snapshot.parent.parent / "refs").mkdir()
    (snapshot.parent.parent / "refs" / "main").write_text(commit)
    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)
    with pytest.warns(UserWarning, match="QuickGELU mismatch"):
        encoder = OpenCLIPEncoder("RN50", pretrained="openai", cache_dir=str(tmp_path))
    assert encoder.dim == 1024
    torch.testing.assert_close(encoder.model.visual.conv1.weight, source.visual.conv1.weight,
                               rtol=0, atol=0)


# ---- the encoder evaluation (reward_quality.encoder_evaluation)


class BrightnessEncoder(Encoder):
    """Embeds a frame as ``[mean brightness, 1]`` and every prompt as ``[1, 0]``: its text-goal
    value csim is v / sqrt(v^2 + 1), which rises with the brightness v."""

    name, dim = "brightness", 2

    def embed_images(self, frames: torch.Tensor) -> torch.Tensor:
        brightness = frames.float().mean(dim=(1, 2, 3))
        return torch.stack([brightness, torch.ones_like(brightness)], -1)

    def _encode_text(self, texts):
        return torch.tensor([[1.0, 0.0]]).expand(len(texts), 2)


def video(brightness: list[int]) -> torch.Tensor:
    return torch.tensor(brightness, dtype=torch.uint8)[:, None, None, None].expand(-1, 4, 4, 3)


def spearman_without_ties(order: list[int]) -> float:
    """rho = 1 - 6 sum d^2 / (n (n^2 - 1)) for values ranked ``order`` against time."""
    n = len(order)
    ranks = sorted(range(n), key=lambda i: order[i])
    rank_of = {index: rank for rank, index in enumerate(ranks)}
    return 1 - 6 * sum((t - rank_of[t]) ** 2 for t in range(n)) / (n * (n * n - 1))


def test_value_order_correlations_equal_the_rank_formula():
    from temporal_torchrl.reward_quality.encoder_evaluation import value_order_correlations

    # Brightness over time; the last frame (the image goal) is the brightest.
    first, second = [10, 30, 20, 50, 40, 90], [5, 15, 25, 35, 80, 45, 95]
    result = value_order_correlations(BrightnessEncoder(), {"drawer-open": [video(first),
                                                                            video(second)]})
    # Text goal: csim rises with brightness, so rho ranks the brightness itself.
    text = (spearman_without_ties(first) + spearman_without_ties(second)) / 2
    # Image goal [V, 1]: for v < V, csim([v, 1], [V, 1]) rises with v; the goal frame left out.
    image = (spearman_without_ties(first[:-1]) + spearman_without_ties(second[:-1])) / 2
    assert result["text"]["drawer-open"] == pytest.approx(text, abs=1e-9)
    assert result["image"]["drawer-open"] == pytest.approx(image, abs=1e-9)
    assert text < 1  # the orders are not monotone, so the check can fail for a wrong rank

    # frame_stride 2 keeps frames 5, 3, 1 of the first video (always the last frame).
    strided = value_order_correlations(BrightnessEncoder(), {"drawer-open": [video(first)]},
                                       frame_stride=2)
    assert strided["text"]["drawer-open"] == pytest.approx(
        spearman_without_ties([first[1], first[3], first[5]]), abs=1e-9)


def test_evaluate_encoders_gives_liv_rows_the_large_videos():
    from temporal_torchrl.envs import EVALUATION_TASKS
    from temporal_torchrl.reward_quality.encoder_evaluation import (
        evaluate_encoders,
        markdown_table,
    )

    rising, falling = video([10, 20, 30, 40]), video([40, 30, 20, 10, 50])
    small = {task: [rising] for task in EVALUATION_TASKS}
    large = {task: [falling] for task in EVALUATION_TASKS}
    rows = evaluate_encoders({"small": BrightnessEncoder, "LIV (random)": BrightnessEncoder},
                             small, large, large_stride=1)
    assert [row["encoder"] for row in rows] == ["small", "LIV (random)"]
    assert rows[0]["mean text-goal rho"] == pytest.approx(1.0)
    assert rows[1]["mean text-goal rho"] == pytest.approx(spearman_without_ties([40, 30, 20,
                                                                                 10, 50]))
    table = markdown_table(rows).splitlines()
    assert table[0].startswith("| encoder |") and "seconds" not in table[0]
    assert len(table) == 4 and "| LIV (random) |" in table[3]
