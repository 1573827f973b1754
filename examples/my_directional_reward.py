"""A directional reward with a hyperparameter of its own, finetuned by a loss of its own; and
D3 finetuned by the built-in directional loss plus one term.

One file: the reward functions, their losses and the registrations that declare them and the
rewards' options. The recipe imports it (``reward.modules``) and sets the options from the
command line:

    python recipes/sac_temporal.py reward.modules=[examples/my_directional_reward.py] \\
        reward.directional=d_sharp +reward.options.sharpness=4 +reward.options.margin=0.2
    python recipes/evaluate_rewards.py reward.modules=[examples/my_directional_reward.py] \\
        reward.positional=none reward.directional=[d3,d_sharp] +reward.options.sharpness=4
    python recipes/sac_temporal.py reward.modules=[examples/my_directional_reward.py] \\
        reward.directional=d3_decay +reward.options.decay=0.001
"""

from __future__ import annotations

import torch

from temporal_torchrl.objectives import DirectionalLoss, FinetuningLoss
from temporal_torchrl.rewards import register_reward
from temporal_torchrl.rewards.directional import d3


# [reward]
def sharpened_d3(heads, s, *, s_prev, g, b, sharpness, position=None, **unused):
    """tanh(sharpness r_D3): D3 with a temperature. A sharpness above 1 pushes the reward of a
    clear direction towards +-1 and keeps a near-sideways one near 0. ``sharpness`` is the
    reward's option: the callers pass its value (the default is the registration's)."""
    return torch.tanh(sharpness * d3(heads, s, s_prev=s_prev, g=g, b=b, position=position))
# [/reward]


# [loss]
class MarginDirectionalLoss(FinetuningLoss):
    """The thesis's directional loss (4.3.3) as a hinge: the observed direction of a failed
    episode must score ``margin`` below the direction towards the goal image, the observed
    direction of a successful one ``margin`` above its opposite; pairs that already do add
    nothing."""

    loss_key = "loss_directional"

    def __init__(self, reward, goal_image_embedding, *, stage):
        super().__init__(reward, reward.directional_heads, goal_image_embedding, stage=stage)

    def terms(self, tensordict):
        """The named terms; ``forward`` sums them into ``loss_directional``."""
        groups, margin = self.groups(tensordict), self.reward.options["margin"]
        # r_D of the direction embedding - previous_embedding, scored at `position`.
        score = self.reward.directional_reward
        parts = {}
        if "negative" in groups:  # stage 1 and 2: states of failed episodes
            s_t, s_tk = groups["negative"]["embedding"], groups["negative"]["previous_embedding"]
            towards_goal = score(self.goal_image_embedding.expand_as(s_t), s_t, position=s_t)
            parts["loss_negative"] = torch.relu(margin + score(s_t, s_tk) - towards_goal).mean()
        if "positive" in groups:  # stage 2: states of successful episodes
            s_t, s_tk = groups["positive"]["embedding"], groups["positive"]["previous_embedding"]
            opposite = score(s_tk, s_t, position=s_t)
            parts["loss_positive"] = torch.relu(margin + opposite - score(s_t, s_tk)).mean()
        return parts
# [/loss]


# [register]
register_reward("d_sharp", sharpened_d3, kind="directional", image_input="concatenated",
                options={"sharpness": 2.0, "margin": 0.1}, loss=MarginDirectionalLoss)
# [/register]


# [extend]
class DecayedDirectionalLoss(DirectionalLoss):
    """The thesis's directional loss (4.3.3) plus one term: ``decay`` times the squared norm of
    the heads' parameters, which keeps them small. The built-in's terms come from
    ``super().terms``, unchanged; the new one is named ``loss_*``, so ``forward`` adds it to
    ``loss_directional`` and reports it beside the built-in's."""

    def terms(self, tensordict):
        terms = super().terms(tensordict)
        squares = torch.stack([parameter.square().sum() for parameter in self.parameters()])
        terms["loss_decay"] = self.reward.options["decay"] * squares.sum()
        return terms


register_reward("d3_decay", d3, kind="directional", image_input="concatenated",
                options={"decay": 1e-3}, loss=DecayedDirectionalLoss)
# [/extend]
