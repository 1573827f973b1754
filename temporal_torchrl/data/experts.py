"""Expert episodes for the replay buffer: embedding and the goal image s_g.

The expert episodes come from :func:`temporal_torchrl.envs.collect_expert_episodes` with the
training run's task, seed and render settings, so their frames are the training frames of the
same layout (the prior code rendered its goal frame at another resolution and always from seed
0's layout; both are avoided by passing the run's own settings).
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase

from temporal_torchrl.encoders import Encoder
from temporal_torchrl.envs import first_success_index


@torch.no_grad()
def embed_episode(episode: TensorDictBase, encoder: Encoder, batch_size: int = 64) -> TensorDict:
    """``episode`` [T] with ``"embedding"`` and ``("next", "embedding")`` added, pixels dropped.

    The ``T + 1`` states are embedded once each (``next`` of step t is the root of step t + 1).
    """
    key = encoder.input_key
    inputs = torch.cat([episode[key][:1], episode["next", key]], 0)
    embeddings = torch.cat([encoder.embed(chunk.to(encoder.device)).float().cpu()
                            for chunk in inputs.split(batch_size)], 0)
    embedded = episode.exclude("pixels", ("next", "pixels"))
    embedded["embedding"] = embeddings[:-1]
    embedded["next", "embedding"] = embeddings[1:]
    return embedded


def goal_image_embedding(episode: TensorDictBase, encoder: Encoder | None = None
                         ) -> torch.Tensor:
    """s_g ``[D]``: the embedding of the first success state of an expert episode.

    The state is ``("next", ...)[t]`` at the first successful step t (the frame rendered after
    that step; with the ``state`` encoder, the observation). An already embedded episode is read
    as it is; otherwise the state is embedded with ``encoder``.
    """
    t = first_success_index(episode)
    if ("next", "embedding") in episode.keys(True):
        return episode["next", "embedding"][t].float().clone()
    if encoder is None:
        raise ValueError("the episode carries no ('next', 'embedding'): pass the encoder that "
                         "embeds the training frames.")
    state = episode["next", encoder.input_key][t:t + 1].to(encoder.device)
    with torch.no_grad():
        return encoder.embed(state)[0].float().cpu()


def goal_image_from_rows(rows: TensorDictBase) -> torch.Tensor:
    """s_g ``[D]`` from an episode's stored rows (:func:`~temporal_torchrl.data.episode_rows`):
    the embedding of its first success state, the state :func:`goal_image_embedding` reads."""
    success = rows["success"].reshape(rows.shape[0], -1).any(-1)
    if not bool(success.any()) or "embedding" not in rows.keys():
        raise ValueError("these rows hold no successful, embedded state: s_g needs a positive "
                         "episode stored with its embeddings.")
    return rows["embedding"][int(success.nonzero()[0, 0])].float().clone()
