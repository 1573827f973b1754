"""StackedCriticSACLoss: TorchRL's SACLoss computed with stacked critics."""

import pytest
import torch
from helpers import config
from torch import nn
from torchrl.modules import MLP, ValueOperator

from temporal_torchrl.configs.rules import Devices
from temporal_torchrl.objectives import StackedQValueNetwork
from temporal_torchrl.training import factories


def test_sac_update_matches_torchrls_sac_loss(tmp_path):
    """The recipe's SAC update (stacked critics, only SAC's keys) against TorchRL's SACLoss as
    its docs build it (vmap over the critics, the whole batch, a TD(0) estimator, SoftUpdate)
    and a plain Adam, from the same weights and random draws: the same losses at each of 3
    updates, and the same actor, critics, target critics and temperature after them."""
    from torchrl.objectives import SACLoss, SoftUpdate

    cfg = config(tmp_path, "reward.directional=d3")
    env = factories.make_environment(cfg, None, None)
    batches = [env.rollout(16, break_when_any_done=False) for _ in range(3)]
    torch.manual_seed(0)
    actor, critics = factories.make_sac_agent(cfg, env, Devices.of(cfg))
    torch.manual_seed(0)
    reference_actor, _ = factories.make_sac_agent(cfg, env, Devices.of(cfg))
    qvalue = ValueOperator(MLP(in_features=43, num_cells=list(cfg.sac.hidden_sizes),
                               out_features=1, activation_class=nn.ReLU),
                           in_keys=["action", "observation"])
    env.close()
    reference = SACLoss(reference_actor, qvalue, num_qvalue_nets=2, loss_function="l2",
                        alpha_init=cfg.sac.alpha_init, target_entropy=-2.0, delay_qvalue=True)
    reference.make_value_estimator(gamma=cfg.sac.gamma)
    target = SoftUpdate(reference, tau=cfg.sac.tau)
    adam = torch.optim.Adam(reference.parameters(), lr=cfg.sac.lr)

    def reference_layers(params):  # SACLoss's critics: ("module", "0", "weight") of [2, out, in]
        layers = [(params["module", index, "weight"], params["module", index, "bias"])
                  for index in sorted(params["module"].keys(), key=int)]
        # ValueOperator reads [action, observation], the stack [observation, action].
        first_weight, first_bias = layers[0]
        layers[0] = (torch.cat([first_weight[..., 4:], first_weight[..., :4]], -1), first_bias)
        return layers

    def assert_stack_is(stack, params):
        for (weight, bias), stacked_weight, stacked_bias in zip(
                reference_layers(params), stack.weights, stack.biases, strict=True):
            torch.testing.assert_close(stacked_weight, weight.transpose(1, 2), rtol=1e-5,
                                       atol=1e-6)
            torch.testing.assert_close(stacked_bias[:, 0], bias, rtol=1e-5, atol=1e-6)

    loss, optimizer = factories.make_sac_loss(cfg, actor, critics, 4)
    with torch.no_grad():  # SACLoss's initial critics, copied into the stack and its targets
        for stack in (loss.critics, loss.target_critics):
            for (weight, bias), stacked_weight, stacked_bias in zip(
                    reference_layers(reference.qvalue_network_params), stack.weights,
                    stack.biases, strict=True):
                stacked_weight.copy_(weight.transpose(1, 2))
                stacked_bias[:, 0].copy_(bias)
    update = factories.make_sac_update(cfg, loss, optimizer)

    keys = ("loss_actor", "loss_qvalue", "loss_alpha", "alpha", "entropy")
    torch.manual_seed(1)
    fast = [update(batch.clone()).select(*keys) for batch in batches]
    torch.manual_seed(1)
    expected = []
    for batch in batches:
        losses = reference(batch.clone())
        (losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_alpha"]).backward()
        adam.step()
        adam.zero_grad()
        target.step()
        expected.append(losses.select(*keys).detach())
    for values, reference_values in zip(fast, expected, strict=True):
        for key in keys:
            torch.testing.assert_close(values[key], reference_values[key], rtol=1e-5, atol=1e-6)
    for parameter, reference_parameter in zip(actor.parameters(), reference_actor.parameters(),
                                              strict=True):
        torch.testing.assert_close(parameter, reference_parameter, rtol=1e-5, atol=1e-6)
    assert_stack_is(loss.critics, reference.qvalue_network_params)
    assert_stack_is(loss.target_critics, reference.target_qvalue_network_params)
    torch.testing.assert_close(loss.log_alpha, reference.log_alpha, rtol=1e-5, atol=1e-6)


def test_stacked_critics_are_independent_mlps():
    """Each slot of the stack is its own MLP: Q_i computed by hand from slot i's weights."""
    torch.manual_seed(0)
    critics = StackedQValueNetwork(3, in_features=5, num_cells=[7, 6])
    observation, action = torch.randn(4, 3), torch.randn(4, 2)
    values = critics(observation, action)
    assert values.shape == (3, 4)
    for slot in range(3):
        features = torch.cat([observation, action], -1)
        for layer, (weight, bias) in enumerate(zip(critics.weights, critics.biases,
                                                   strict=True)):
            features = features @ weight[slot] + bias[slot, 0]
            if layer < 2:
                features = features.clamp_min(0)
        torch.testing.assert_close(values[slot], features.squeeze(-1))
    assert not torch.equal(values[0], values[1])


def test_a_stack_without_critics_is_refused():
    with pytest.raises(ValueError, match="at least 1"):
        StackedQValueNetwork(0, in_features=5, num_cells=[8])


def test_inputs_of_the_wrong_size_are_refused_not_reshaped():
    """4 states of 3 + 2 features fill 20 values, which a 4-feature stack could reshape into 5
    rows: the stack refuses them instead."""
    critics = StackedQValueNetwork(2, in_features=4, num_cells=[8])
    with pytest.raises(ValueError, match="in_features = observation"):
        critics(torch.randn(4, 3), torch.randn(4, 2))
