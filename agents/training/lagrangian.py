"""PPO-Lagrangian: stable-baselines3's PPO with a cost critic and a Lagrange multiplier.

The constrained problem of safe RL (Altman 1999; Ray, Achiam & Amodei 2019, the
Safety Gym paper's PPO-Lagrangian; OmniSafe's ``PPOLag``): maximise the return subject
to J_c <= d, with J_c the mean cost per step (the env's ``info["cost"]``,
:mod:`tether_gym.tasks.cost`) and d = ``cost_limit``. It is solved as the saddle
point of L(pi, lambda) = J_r(pi) - lambda (J_c(pi) - d), lambda >= 0:

* **Cost critic.** A second value network V_c(s) (the policy's ``net_arch`` for the
  value, tanh, on the observation the policy sees) is fitted to the discounted cost
  returns, and the cost advantages A_c come from GAE(gamma, lambda_GAE) on the costs,
  exactly as the reward's (truncated episodes bootstrap with gamma V_c of the final
  observation, as SB3 does for the reward).
* **Policy.** PPO's clipped surrogate is taken on the advantage
  (A_r - lambda A_c) / (1 + lambda), with A_r and A_c each standardised over the
  rollout first (OmniSafe's ``PPOLag``), so lambda = 1 weighs them equally.
* **Multiplier.** Before each update, lambda <- max(0, lambda + ``lagrange_lr``
  (J_c - d) / d), with J_c the rollout's mean cost per step: projected gradient ascent
  on the relative violation (lambda grows by ``lagrange_lr`` per rollout spent at
  twice the limit), from ``lagrange_init``.

Everything else (rollouts, reward critic, clipping, the policy class) is PPO's, so the
policy is an ``ActorCriticPolicy`` and an agent file of it loads and evaluates like a PPO
agent's. The cost critic, its optimizer and lambda are saved in the model zip beside
the policy (``_get_torch_save_params``), so ``train.py --resume`` continues them.
"""

from __future__ import annotations

import inspect
from typing import Any, cast

import numpy as np
import torch as th
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.utils import obs_as_tensor
from torch import nn
from torch.nn import functional as F

from tether_gym.tasks.cost import COST_LIMIT
from tether_gym_agents.training.caps import signature_with

__all__ = ["PPOLagrangian"]


class _CostHook:
    """Passes SB3's rollout callback calls on, recording each step's cost first."""

    def __init__(self, model: PPOLagrangian, inner):
        self.model = model
        self.inner = inner
        self.locals: dict[str, Any] = {}

    def on_rollout_start(self) -> None:
        self.inner.on_rollout_start()

    def update_locals(self, locals_: dict[str, Any]) -> None:
        self.locals = locals_
        self.inner.update_locals(locals_)

    def on_step(self) -> bool:
        self.model._record_costs(self.locals)
        return self.inner.on_step()

    def on_rollout_end(self) -> None:
        self.model._finish_costs(self.locals)
        self.inner.on_rollout_end()


def _standardised(x: np.ndarray) -> np.ndarray:
    std = float(x.std())
    return (x - x.mean()) / std if std > 1e-8 else np.zeros_like(x)


class PPOLagrangian(PPO):
    """PPO with a cost constraint (module docstring); ``train.py --algo ppo_lag``.

    Parameters
    ----------
    cost_limit : float
        d [-], the limit on the mean cost per step, >= 0 (the benchmark's COST_LIMIT,
        0.01, by default).
    lagrange_lr : float
        Step of lambda per rollout per unit of relative violation (J_c - d) / d, >= 0.
    lagrange_init : float
        lambda at the start, >= 0.
    failure_cost : float
        Cost added, for the cost critic only, to a step that terminates the episode
        (a failure), >= 0. 0 (the default) leaves a terminated episode costing nothing
        more, which makes ending it the cheapest way to lower the discounted cost (the
        first shipped row learned exactly that); 1 / (1 - gamma) prices the failure as a
        state that keeps costing 1 per step (``configs/ppo_lag.yml``: 200). J_c (the
        multiplier's input) counts the env's costs only.
    *args, **kwargs
        PPO's.
    """

    def __init__(self, *args, cost_limit: float = COST_LIMIT, lagrange_lr: float = 0.05,
                 lagrange_init: float = 0.0, failure_cost: float = 0.0, **kwargs):
        self.cost_limit = float(cost_limit)
        self.lagrange_lr = float(lagrange_lr)
        self.lagrange_init = float(lagrange_init)
        self.failure_cost = float(failure_cost)
        super().__init__(*args, **kwargs)

    def _setup_model(self) -> None:
        super()._setup_model()
        shape = self.observation_space.shape
        obs_dim = int(np.prod(shape if shape is not None else ()))
        arch = self.policy.net_arch
        layers = list(arch.get("vf", [64, 64]) if isinstance(arch, dict) else arch)
        modules: list[nn.Module] = []
        width = obs_dim
        for size in layers:
            modules += [nn.Linear(width, size), nn.Tanh()]
            width = size
        modules.append(nn.Linear(width, 1))
        self.cost_critic = nn.Sequential(*modules).to(self.device)
        self.cost_optimizer = th.optim.Adam(self.cost_critic.parameters(),
                                            lr=self.lr_schedule(1.0))
        self.lagrange_multiplier = th.tensor(self.lagrange_init, dtype=th.float32)
        shape = (self.n_steps, self.n_envs)
        self._costs = np.zeros(shape, dtype=np.float32)
        self._env_costs = np.zeros(shape, dtype=np.float32)
        self._cost_values = np.zeros(shape, dtype=np.float32)
        self._cost_advantages = np.zeros(shape, dtype=np.float32)
        self._cost_returns = np.zeros(shape, dtype=np.float32)

    # ------------------------------------------------------------------ #
    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts, variables = super()._get_torch_save_params()
        return [*state_dicts, "cost_critic", "cost_optimizer"], [*variables,
                                                                 "lagrange_multiplier"]

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_costs", "_env_costs", "_cost_values",
                "_cost_advantages", "_cost_returns"]

    def _cost_value(self, obs) -> np.ndarray:
        with th.no_grad():
            tensor = obs if isinstance(obs, th.Tensor) else obs_as_tensor(obs, self.device)
            assert isinstance(tensor, th.Tensor)  # a Box observation
            return self.cost_critic(tensor.float().reshape(tensor.shape[0], -1)) \
                .cpu().numpy().ravel()

    # ------------------------------------------------------------------ #
    def collect_rollouts(self, env, callback, rollout_buffer, n_rollout_steps: int) -> bool:
        """PPO's rollout, with each step's cost recorded (and its GAE at the end)."""
        hook = cast(BaseCallback, _CostHook(self, callback))  # the calls SB3 makes, passed on
        return super().collect_rollouts(env, hook, rollout_buffer,
                                        n_rollout_steps)

    def _record_costs(self, locals_: dict[str, Any]) -> None:
        """The step's cost and V_c(s) at the slot the rollout buffer is about to fill."""
        infos = locals_["infos"]
        costs = np.empty(len(infos), dtype=np.float32)
        for i, info in enumerate(infos):
            if "cost" not in info:
                raise ValueError("ppo_lag needs an env whose info has 'cost' "
                                 "(tether_gym/TetherLibration-v2); this env's info keys: "
                                 f"{sorted(info)}")
            costs[i] = float(info["cost"])
        self._env_costs[self.rollout_buffer.pos] = costs
        for i, info in enumerate(infos):
            if locals_["dones"][i] and not info.get("TimeLimit.truncated", False):
                costs[i] += self.failure_cost
            if locals_["dones"][i] and info.get("terminal_observation") is not None \
                    and info.get("TimeLimit.truncated", False):
                costs[i] += self.gamma * self._cost_value(
                    np.asarray(info["terminal_observation"])[None])[0]
        pos = self.rollout_buffer.pos
        self._costs[pos] = costs
        self._cost_values[pos] = self._cost_value(locals_["obs_tensor"])

    def _finish_costs(self, locals_: dict[str, Any]) -> None:
        """GAE of the costs over the rollout (RolloutBuffer's recursion)."""
        last_values = self._cost_value(locals_["new_obs"])
        dones = np.asarray(locals_["dones"], dtype=np.float32)
        starts = self.rollout_buffer.episode_starts
        gae = np.zeros(self.n_envs, dtype=np.float32)
        for step in reversed(range(self.n_steps)):
            if step == self.n_steps - 1:
                nonterminal, next_values = 1.0 - dones, last_values
            else:
                nonterminal, next_values = 1.0 - starts[step + 1], self._cost_values[step + 1]
            delta = (self._costs[step] + self.gamma * next_values * nonterminal
                     - self._cost_values[step])
            gae = delta + self.gamma * self.gae_lambda * nonterminal * gae
            self._cost_advantages[step] = gae
        self._cost_returns[:] = self._cost_advantages + self._cost_values

    # ------------------------------------------------------------------ #
    def train(self) -> None:
        """Update lambda, then PPO's update on the combined advantage, then the cost critic."""
        rate = float(np.mean(self._env_costs))  # J_c: the env's costs, no bootstrap
        violation = (rate - self.cost_limit) / max(self.cost_limit, 1e-8)
        lam = max(0.0, float(self.lagrange_multiplier) + self.lagrange_lr * violation)
        self.lagrange_multiplier.fill_(lam)
        buffer = self.rollout_buffer
        combined = (_standardised(buffer.advantages) - lam * _standardised(
            self._cost_advantages)) / (1.0 + lam)
        buffer.advantages[:] = combined
        super().train()
        value_loss = self._train_cost_critic()
        self.logger.record("train/lagrange_multiplier", lam)
        self.logger.record("train/cost_rate", rate)
        self.logger.record("train/cost_value_loss", value_loss)

    def _train_cost_critic(self) -> float:
        obs = th.as_tensor(self.rollout_buffer.observations, device=self.device).float()
        obs = obs.reshape(self.n_steps * self.n_envs, -1)
        target = th.as_tensor(self._cost_returns.reshape(-1), device=self.device)
        for group in self.cost_optimizer.param_groups:
            group["lr"] = self.policy.optimizer.param_groups[0]["lr"]
        losses = []
        for _ in range(self.n_epochs):
            order = th.randperm(obs.shape[0], device=self.device)
            for start in range(0, obs.shape[0], self.batch_size):
                idx = order[start:start + self.batch_size]
                loss = F.mse_loss(self.cost_critic(obs[idx]).squeeze(-1), target[idx])
                self.cost_optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(self.cost_critic.parameters(), self.max_grad_norm)
                self.cost_optimizer.step()
                losses.append(loss.item())
        return float(np.mean(losses)) if losses else 0.0


_OWN_KEYWORDS = tuple((name, p.default) for name, p in
                      inspect.signature(PPOLagrangian.__init__).parameters.items()
                      if p.kind is inspect.Parameter.KEYWORD_ONLY)
PPOLagrangian.__init__.__signature__ = signature_with(  # type: ignore[attr-defined]
    PPO, _OWN_KEYWORDS)
