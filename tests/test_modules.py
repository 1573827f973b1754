"""temporal_torchrl.modules.relu: ReLU's values and gradient, eager and compiled, and no boolean
mask saved between the compiled forward and backward (what makes inductor's CPU code slow)."""

import pytest
import torch
from functorch.compile import min_cut_rematerialization_partition
from torch import nn
from torch._dynamo.backends.common import aot_autograd
from torch._inductor.decomposition import select_decomp_table

from temporal_torchrl.modules import ReLU, relu


def layer(activation, train_second: bool = True):
    """A linear layer then ``activation`` then a second linear layer (the heads' MLP shape);
    without ``train_second`` the second layer is frozen, as the critics are in SAC's actor
    loss, so the backward needs the activation's mask but not its output."""
    torch.manual_seed(0)
    first, second = nn.Linear(8, 16), nn.Linear(16, 3).requires_grad_(train_second)
    return lambda x: second(activation(first(x))).square().sum()


@pytest.mark.parametrize("compiled", [False, True])
def test_relu_gives_torchs_values_and_gradients(compiled):
    x = torch.randn(32, 8)
    x[:4] = 0.0  # outputs exactly at the kink: torch's gradient there is 0
    grads = []
    for activation in (torch.relu, relu):
        fn = layer(activation)
        fn = torch.compile(fn) if compiled and activation is relu else fn
        inputs = x.clone().requires_grad_(True)
        value = fn(inputs)
        value.backward()
        grads.append((value.detach(), inputs.grad))
    (torch_value, torch_grad), (value, grad) = grads
    torch.testing.assert_close(value, torch_value)
    torch.testing.assert_close(grad, torch_grad)


def saved_between_forward_and_backward(activation) -> list[torch.dtype]:
    """The dtypes the compiled forward graph hands the backward, with inductor's decompositions
    and partitioner (the graphs themselves then run as traced, not through inductor)."""
    saved = []

    def forward_compiler(graph, example_inputs):
        outputs = next(node for node in graph.graph.nodes if node.op == "output").args[0]
        saved.extend(node.meta["val"].dtype for node in outputs[1:])  # [0]: the loss itself
        return graph

    backend = aot_autograd(fw_compiler=forward_compiler,
                           bw_compiler=lambda graph, example_inputs: graph,
                           partition_fn=min_cut_rematerialization_partition,
                           decompositions=select_decomp_table())
    compiled = torch.compile(layer(activation, train_second=False), backend=backend)
    compiled(torch.randn(32, 8, requires_grad=True))
    return saved


def test_compiled_relu_saves_no_boolean_mask():
    assert torch.bool in saved_between_forward_and_backward(torch.relu)  # what it avoids
    assert torch.bool not in saved_between_forward_and_backward(relu)


def test_relu_module_is_a_drop_in_for_nn_relu():
    torch.manual_seed(0)
    ours = nn.Sequential(nn.Linear(4, 8), ReLU(), nn.Linear(8, 2))
    torch.manual_seed(0)
    theirs = nn.Sequential(nn.Linear(4, 8), nn.ReLU(), nn.Linear(8, 2))
    assert ours.state_dict().keys() == theirs.state_dict().keys()
    x = torch.randn(5, 4)
    torch.testing.assert_close(ours(x), theirs(x))
