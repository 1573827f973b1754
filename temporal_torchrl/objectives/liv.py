"""LIV's pretraining objective (Ma et al., ICML 2023) as a loss module.

LIV ("Language-Image Value learning") trains an image encoder ``phi`` and a text encoder
``psi`` so that the cosine similarity between a frame and a goal (a goal frame or a goal
text) is a value function: it rises along successful videos towards their goal. The
objective has three parts, all with the similarity ``S(x, y) = cos(x, y)`` (LIV's
similarity: cosine, no temperature) and the value ``V(o; g) = S(phi(o), e_g)``.

1. VIP's temporal value objective with the last frame of the video as the goal
   (``e_g = phi(o_g)``; Ma et al., VIP, ICLR 2023, eq. 6, with LIV's cosine value)::

       L_VIP(e_g) = (1 - gamma) * E[-V(o_0; g)]
                    + log E[exp(-(r + gamma * V(o_{t+1}; g) - V(o_t; g)))]

   where ``o_0`` is the first frame of the sampled segment, ``(o_t, o_{t+1})`` consecutive
   frames of the same video before the goal and ``r = -1`` (VIP's reward ``1[o_t = g] - 1``;
   ``o_t`` is never the goal frame itself). Minimising the log-mean-exp term pushes
   ``V(o_{t+1}; g)`` above ``V(o_t; g) / gamma``, i.e. values that increase along the video,
   while the first term pulls the start frame towards the goal so that the embedding does
   not collapse to the trivial solution (VIP's implicit time-contrastive effect).
2. The same objective with the task's text as the goal (``e_g = psi(l)``), LIV's
   language-goal value: ``L_VIP(psi(l))``. This is what makes ``csim(phi(o_t), psi(l))``
   a zero-shot reward.
3. A CLIP-style InfoNCE term that ties each goal frame to its task text, symmetric over
   images and texts, with temperature ``tau``::

       L_NCE = -1/2 E_i[log sum_{j in P(i)} softmax_j(S(phi(o_g^i), psi(l^j)) / tau)]
               -1/2 E_j[log sum_{i in P(j)} softmax_i(S(phi(o_g^i), psi(l^j)) / tau)]

   ``P(i)`` are the batch entries with the same task as entry ``i`` (several videos of one
   task share a text, so they are positives, not negatives, of each other).

Total: ``L = w_image * L_VIP(phi(o_g)) + w_text * L_VIP(psi(l)) + w_nce * L_NCE``.

Assumptions (stated because the reference code was not available while writing this): the
value is the plain cosine similarity by default (``value_scale=1``), ``gamma = 0.98`` as in
VIP/LIV, ``epsilon`` inside the log as in VIP's code, no extra shuffled negatives, and a fixed
InfoNCE temperature ``tau = 0.1`` (LIV keeps CLIP's ``logit_scale`` in its weights but its
reward does not use it).

``value_scale`` (``V = kappa * S``): with ``kappa = 1`` values live in [-1, 1] while the
reward is -1 per step, so every collapsed embedding (all ``S`` equal) gives the same loss, 1,
and the temporal term's gradient is weak; training a small encoder from
scratch on a CPU budget, ``recipes/pretrain_encoder.py`` uses ``kappa = 10``. A positive scale
leaves the order of values, hence the zero-shot reward's ranking, unchanged.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from tensordict import TensorDict
from torch import nn


class LIVLoss(nn.Module):
    """LIV's objective on precomputed embeddings; returns a TensorDict of loss terms.

    The module holds no parameters: the encoders stay outside, so any image/text tower pair
    can be trained with it (``recipes/pretrain_encoder.py`` trains the small encoder).

    Args:
        gamma: discount of the value objective (VIP and LIV use 0.98).
        value_scale: ``V = value_scale * S``; 1 is LIV's cosine value.
        temperature: ``tau`` of the InfoNCE term.
        image_goal_weight, text_goal_weight, contrastive_weight: weights of the three terms.
        epsilon: added inside the log of the log-mean-exp, as in VIP's code.

    Example:
        >>> import torch
        >>> from temporal_torchrl.objectives.liv import LIVLoss
        >>> loss = LIVLoss()
        >>> e = lambda: torch.randn(8, 16)
        >>> out = loss(initial=e(), current=e(), next=e(), goal=e(), text=e(),
        ...            task_ids=torch.arange(8) % 3)
        >>> sorted(k for k in out.keys() if k.startswith("loss"))
        ['loss', 'loss_contrastive', 'loss_vip_image', 'loss_vip_text']
    """

    def __init__(self, gamma: float = 0.98, value_scale: float = 1.0, temperature: float = 0.1,
                 image_goal_weight: float = 1.0, text_goal_weight: float = 1.0,
                 contrastive_weight: float = 1.0, epsilon: float = 1e-6) -> None:
        super().__init__()
        if not 0.0 < gamma < 1.0:
            raise ValueError(f"gamma={gamma} is outside (0, 1): use a discount such as 0.98.")
        if temperature <= 0.0 or value_scale <= 0.0:
            raise ValueError(
                f"temperature={temperature} and value_scale={value_scale} must both be "
                "positive: use e.g. temperature=0.1, value_scale=1.0."
            )
        self.gamma = gamma
        self.value_scale = value_scale
        self.temperature = temperature
        self.image_goal_weight = image_goal_weight
        self.text_goal_weight = text_goal_weight
        self.contrastive_weight = contrastive_weight
        self.epsilon = epsilon

    def value(self, embedding: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """``V(o; g) = value_scale * cos(phi(o), e_g)`` over the last dimension."""
        return self.value_scale * F.cosine_similarity(embedding, goal, dim=-1)

    def vip_loss(self, initial: torch.Tensor, current: torch.Tensor, next: torch.Tensor,
                 goal: torch.Tensor, reward: torch.Tensor | None = None) -> torch.Tensor:
        """VIP's objective ``L_VIP(e_g)`` (module docstring, term 1) for ``[B, D]`` inputs.

        ``reward`` defaults to -1 for every pair (``o_t`` is not the goal).
        """
        if reward is None:
            reward = torch.full(current.shape[:-1], -1.0, device=current.device,
                                dtype=current.dtype)
        value_initial = self.value(initial, goal)
        value_current = self.value(current, goal)
        value_next = self.value(next, goal)
        temporal_difference = reward + self.gamma * value_next - value_current
        return ((1.0 - self.gamma) * -value_initial.mean()
                + torch.log(self.epsilon + torch.exp(-temporal_difference).mean()))

    def contrastive_loss(self, goal: torch.Tensor, text: torch.Tensor,
                         task_ids: torch.Tensor | None = None) -> torch.Tensor:
        """Symmetric multi-positive InfoNCE between goal frames and texts (term 3)."""
        logits = F.normalize(goal, dim=-1) @ F.normalize(text, dim=-1).T / self.temperature
        if task_ids is None:
            task_ids = torch.arange(goal.shape[0], device=goal.device)
        positives = task_ids[:, None] == task_ids[None, :]
        image_to_text = torch.logsumexp(logits.masked_fill(~positives, float("-inf")), dim=1) \
            - torch.logsumexp(logits, dim=1)
        text_to_image = torch.logsumexp(logits.masked_fill(~positives, float("-inf")), dim=0) \
            - torch.logsumexp(logits, dim=0)
        return -0.5 * (image_to_text.mean() + text_to_image.mean())

    def forward(self, initial: torch.Tensor, current: torch.Tensor, next: torch.Tensor,
                goal: torch.Tensor, text: torch.Tensor,
                task_ids: torch.Tensor | None = None) -> TensorDict:
        """Loss terms for a batch of ``B`` samples, each from one video.

        Args:
            initial: ``phi(o_0)`` ``[B, D]``, first frame of each sampled segment.
            current, next: ``phi(o_t)``, ``phi(o_{t+1})`` ``[B, D]``, consecutive frames.
            goal: ``phi(o_g)`` ``[B, D]``, the video's last (goal) frame.
            text: ``psi(l)`` ``[B, D]``, the video's task text.
            task_ids: int ``[B]``; samples with equal ids share a text (InfoNCE positives).
                Default: all different.

        Returns:
            TensorDict with ``loss`` (the weighted sum), ``loss_vip_image``, ``loss_vip_text``,
            ``loss_contrastive`` and detached diagnostics ``value_increase_image`` /
            ``value_increase_text`` (fraction of pairs with ``V(o_{t+1}) > V(o_t)``).
        """
        shapes = {tuple(t.shape) for t in (initial, current, next, goal, text)}
        if len(shapes) != 1 or initial.dim() != 2:
            raise ValueError(
                f"embeddings have shapes {sorted(shapes)}: expected initial, current, next, goal "
                "and text all of the same shape [B, D]."
            )
        loss_vip_image = self.vip_loss(initial, current, next, goal)
        loss_vip_text = self.vip_loss(initial, current, next, text)
        loss_contrastive = self.contrastive_loss(goal, text, task_ids)
        loss = (self.image_goal_weight * loss_vip_image + self.text_goal_weight * loss_vip_text
                + self.contrastive_weight * loss_contrastive)
        with torch.no_grad():
            increase_image = (self.value(next, goal) > self.value(current, goal)).float().mean()
            increase_text = (self.value(next, text) > self.value(current, text)).float().mean()
        return TensorDict({
            "loss": loss,
            "loss_vip_image": loss_vip_image,
            "loss_vip_text": loss_vip_text,
            "loss_contrastive": loss_contrastive,
            "value_increase_image": increase_image,
            "value_increase_text": increase_text,
        }, batch_size=[])
