"""The small Metaworld encoder (temporal_torchrl.encoders.small) and its shipped weights."""

import pytest
import torch

from temporal_torchrl.encoders.small import DEFAULT_WEIGHTS, SmallEncoder


@pytest.fixture(scope="module")
def shipped() -> SmallEncoder:
    return SmallEncoder.from_pretrained()


def test_shipped_weights_are_small_and_load_without_unpickling_code():
    assert DEFAULT_WEIGHTS.is_file()
    assert DEFAULT_WEIGHTS.stat().st_size <= 20 * 1024 * 1024
    payload = torch.load(DEFAULT_WEIGHTS, map_location="cpu", weights_only=True)
    assert set(payload) == {"state_dict", "config"}
    assert payload["config"]["name"] == "metaworld_small"


def test_load_encoder_builds_the_shipped_encoder_offline(shipped):
    from temporal_torchrl.encoders import ENCODERS, load_encoder

    assert "metaworld_small" in ENCODERS
    encoder = load_encoder("metaworld_small")
    assert isinstance(encoder, SmallEncoder)
    assert encoder.name == "metaworld_small" and encoder.input_key == "pixels"
    frames = torch.randint(0, 256, (3, 64, 64, 3), dtype=torch.uint8)
    torch.testing.assert_close(encoder.embed_images(frames), shipped.embed_images(frames))


def test_shipped_encoder_is_frozen_and_differs_from_random_weights(shipped):
    assert not any(p.requires_grad for p in shipped.parameters())
    assert not shipped.training
    torch.manual_seed(0)
    random = SmallEncoder(**shipped.config()).freeze()
    frames = torch.randint(0, 256, (2, 64, 64, 3), dtype=torch.uint8)
    assert not torch.allclose(shipped.embed_images(frames), random.embed_images(frames))


@pytest.mark.parametrize("size", [64, 100, 224])
def test_image_embeddings_have_the_documented_shape_and_dtype(shipped, size):
    frames = torch.randint(0, 256, (5, size, size, 3), dtype=torch.uint8)
    embeddings = shipped.embed(frames)
    assert embeddings.shape == (5, shipped.dim) and embeddings.dtype == torch.float32
    assert torch.isfinite(embeddings).all()
    # A frame's embedding does not depend on the rest of the batch.
    torch.testing.assert_close(shipped.embed_images(frames[:1]), embeddings[:1],
                               rtol=1e-4, atol=1e-5)


def test_text_embeddings_are_cached_per_prompt(shipped):
    shipped.clear_text_cache()
    texts = ["open a drawer", "robot arm beside table", "open a drawer"]
    embeddings = shipped.embed_text(texts)
    assert embeddings.shape == (3, shipped.dim) and embeddings.dtype == torch.float32
    assert set(shipped._text_cache) == {"open a drawer", "robot arm beside table"}
    torch.testing.assert_close(embeddings[0], embeddings[2])
    assert not torch.allclose(embeddings[0], embeddings[1])
    torch.testing.assert_close(shipped.embed_text(["open a drawer"])[0], embeddings[0])


def test_save_and_load_round_trip(tmp_path):
    torch.manual_seed(1)
    encoder = SmallEncoder(image_size=32, embedding_dim=16, width=8, token_dim=8,
                           name="tiny").freeze()
    path = tmp_path / "tiny.pt"
    encoder.save(path, dtype=torch.float32)
    loaded = SmallEncoder.from_pretrained(path)
    assert loaded.config() == encoder.config()
    frames = torch.randint(0, 256, (2, 48, 48, 3), dtype=torch.uint8)
    torch.testing.assert_close(loaded.embed_images(frames), encoder.embed_images(frames))
    torch.testing.assert_close(loaded.embed_text(["push"]), encoder.embed_text(["push"]))


def test_bad_inputs_raise_value_errors(shipped, tmp_path):
    with pytest.raises(ValueError, match="image_size"):
        SmallEncoder(image_size=50)
    with pytest.raises(ValueError, match="shape"):
        shipped.embed_images(torch.zeros(64, 64, 3, dtype=torch.uint8))
    with pytest.raises(ValueError, match="list of strings"):
        shipped.embed_text("open a drawer")
    with pytest.raises(ValueError, match="does not exist"):
        SmallEncoder.from_pretrained(tmp_path / "missing.pt")
    torch.save({"weights": torch.zeros(1)}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a small-encoder checkpoint"):
        SmallEncoder.from_pretrained(tmp_path / "other.pt")


def test_frames_far_smaller_than_the_encoder_reads_are_refused_or_warned_about(shipped):
    """The recipe's env.image_size=7 with the 64-px shipped encoder stops before any env is
    built, naming the size it expects; 24 px (upsampled 2.7x) is warned about; 32 px and up, a
    (height, width) pair, and encoders that read no pixels pass silently."""
    import warnings

    from temporal_torchrl.encoders import load_encoder
    from temporal_torchrl.encoders.preprocessing import make_preprocessor
    from temporal_torchrl.envs import make_temporal_env

    assert shipped.frame_size == 64
    with pytest.raises(ValueError, match=r"frames of 7x7 px are far smaller than the 64x64 px "
                       r"frames the 'metaworld_small' encoder was trained on.*upsamples them "
                       r"9\.1x.*env\.image_size=64"):
        make_temporal_env("drawer-open", encoder=shipped, image_size=7)
    with pytest.warns(UserWarning, match=r"frames of 24x24 px are smaller than the 64x64.*2\.7x"):
        shipped.check_frame_size(24)
    with pytest.warns(UserWarning, match="frames of 64x20 px"):
        shipped.check_frame_size((64, 20))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for size in (32, 64, 256, (48, 64)):
            shipped.check_frame_size(size)
        load_encoder("state", dim=8).check_frame_size(7)
    # LIV and open_clip read 224-px frames (the prior Metaworld crop needs 224 px of frame).
    assert make_preprocessor("liv").frame_size == 224
    assert make_preprocessor("metaworld_prior").frame_size == 224
