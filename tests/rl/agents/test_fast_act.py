"""The fast batch-1 decision path gives exactly the actions of the plain network: QNetwork.forward calls F.linear on
the layers' Parameters instead of nn.Sequential, and Policy.act skips the forward pass when every robot escapes."""

import copy

import pytest
import torch

from dtradar_rl.agents.policy import Policy, QNetwork, _escape_generator
from dtradar_rl.envs.memory import flag_columns
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for

DIM = 48 + 2 * 11**2 + 1  # the default agent: neighbors + a radius-5 window of two maps + visits_here


def plain_act(p: Policy, obs: torch.Tensor, shield: bool, gen: torch.Generator) -> torch.Tensor:
    """Policy.act as first written: nn.Sequential, then the shield, then the escape (random draws from ``gen``)."""
    with torch.no_grad():
        q = p.q.net(obs)
        if shield:
            flags = obs[..., p.shield_columns()] > 0.5
            q = torch.where(flags | ~flags.any(-1, keepdim=True), q, torch.full_like(q, -torch.inf))
        action = q.argmax(-1)
    k = p.escape_after
    if k:
        stuck = obs[..., -1] >= k
        if bool(stuck.any()):
            if shield:
                score = torch.rand(q.shape, generator=gen)
                moves = torch.where(flags | ~flags.any(-1, keepdim=True), score, -1.0).argmax(-1)
            else:
                moves = torch.randint(4, action.shape, generator=gen)
            action = torch.where(stuck, moves, action)
    return action


def random_obs(n: int, gen: torch.Generator, stuck: float) -> torch.Tensor:
    """Random observations: ~half the has-radio flags set, ``visits_here`` >= 2 (the escape) with probability
    ``stuck``."""
    obs = torch.randn(n, DIM, generator=gen)
    obs[:, flag_columns()] = (torch.rand(n, 4, generator=gen) < 0.5).float()
    obs[:, -1] = torch.where(
        torch.rand(n, generator=gen) < stuck, 2.0, torch.randint(0, 2, (n,), generator=gen).float()
    )
    return obs


def config_policy(escape_after: int) -> Policy:
    torch.manual_seed(0)
    ds = load_dataset("synthetic-12x8/blueprint")
    cfg = config_for("memory-escape", scene="synthetic-12x8", escape_after=escape_after)
    return Policy(QNetwork(DIM, (256, 256)), cfg, Normalizer.fit(ds), "neighbors", {})


def test_the_network_gives_the_values_of_its_sequential_layers_bit_for_bit_after_copies_and_loads():
    q = QNetwork(DIM, (256, 256))
    x = torch.randn(64, DIM)
    assert torch.equal(q(x), q.net(x)) and torch.equal(q(x[:1]), q.net(x[:1]))
    twin = copy.deepcopy(q)  # the DQN target network
    with torch.no_grad():
        twin.net[0].weight.add_(1.0)
    assert torch.equal(twin(x), twin.net(x)) and not torch.equal(twin(x), q(x))
    q.load_state_dict(twin.state_dict())
    q.to(torch.float64).to(torch.float32)
    assert torch.equal(q(x), twin.net(x))
    torch.__future__.set_overwrite_module_params_on_conversion(True)  # .to() makes new Parameters
    try:
        q.to(torch.float64)
    finally:
        torch.__future__.set_overwrite_module_params_on_conversion(False)
    assert torch.equal(q(x.double()), q.net(x.double()))
    q.load_state_dict(QNetwork(DIM, (256, 256)).double().state_dict(), assign=True)
    assert torch.equal(q(x.double()), q.net(x.double())) and not torch.equal(q.net(x.double()), twin(x).double())
    q.float()
    loss = q(x).sum()  # training goes through the same Parameters
    loss.backward()
    assert all(p.grad is not None for p in q.parameters())


@pytest.mark.parametrize("shield", [False, True])
@pytest.mark.parametrize("escape_after", [0, 2])
def test_act_gives_the_plain_networks_actions_one_robot_at_a_time_and_in_batches(shield, escape_after):
    p = config_policy(escape_after)
    p.escape_gen = None
    ref_gen = _escape_generator(torch.device("cpu"))
    gen = torch.Generator().manual_seed(1)
    for n, stuck in [(1, 0.3)] * 300 + [(257, 0.0), (257, 0.3), (64, 1.0), (0, 0.5)]:
        obs = random_obs(n, gen, stuck)
        assert torch.equal(p.act(obs, shield=shield), plain_act(p, obs, shield, ref_gen))
