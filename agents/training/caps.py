"""SAC and TQC with optional action-smoothness terms in the actor loss (CAPS, Mysore et al. 2021).

:class:`CapsSAC` is the class ``train.py --algo sac`` trains, :class:`CapsTQC` (made on
first use, from sb3-contrib's TQC: ``pip install sb3-contrib``) the one of ``--algo
tqc``: the library's algorithm with up to three penalties added to the actor loss, each
on the policy's deterministic action mu(s) = tanh(mean(s)) in [-1, 1] (no sampling
noise):

* temporal, ``caps_temporal`` * mean ||mu(s_t) - mu(s_t+1)||^2 over the replay batch's
  transitions (CAPS's L_T);
* spatial, ``caps_spatial`` * mean ||mu(s) - mu(s + n)||^2 with n ~ N(0, ``caps_sigma``^2)
  in the (normalised) observation the policy sees (CAPS's L_S);
* magnitude, ``caps_magnitude`` * mean ||mu(s)||^2. Under ``action_mode="increment"``
  the action is the change of the reel command, so this is the temporal smoothness of
  the command itself (the chattering metric is the total variation of the reel rates).

With all three weights 0 (the default) the update is the library's own ``train``, step
for step. With a weight on, :meth:`CapsMixin.train` runs the update loop of
stable-baselines3 2.x's ``SAC.train`` (which sb3-contrib's ``TQC.train`` shares line for
line but for the critic's target and loss and the actor's value of its action: the two
hooks :meth:`CapsMixin._critic_loss` and :meth:`CapsMixin._actor_value`) with the
penalties added. The weights are on the scale of the actor loss, alpha log pi - Q, and
Q is of the order of the discounted return.
"""

from __future__ import annotations

import inspect
from typing import TYPE_CHECKING, Any

import numpy as np
import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.utils import polyak_update
from torch.nn import functional as F

from ..common.algorithms import ALGORITHMS

__all__ = ["CapsMixin", "CapsSAC", "caps_tqc_class", "smoothness_terms"]

CAPS_DEFAULTS = (("caps_temporal", 0.0), ("caps_spatial", 0.0), ("caps_magnitude", 0.0),
                 ("caps_sigma", 0.05))
"""The smoothness keyword arguments and their defaults (all terms off)."""


def smoothness_terms(actor, obs: th.Tensor, next_obs: th.Tensor, sigma: float
                     ) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
    """(temporal, spatial, magnitude) penalties of ``actor``'s deterministic action.

    Each is a mean over the batch of a squared distance in the action box, summed over
    the action's entries. The spatial term is 0 (and draws no random numbers) for
    ``sigma`` 0.
    """
    mu = actor(obs, deterministic=True)
    mu_next = actor(next_obs, deterministic=True)
    temporal = (mu - mu_next).pow(2).sum(dim=1).mean()
    magnitude = mu.pow(2).sum(dim=1).mean()
    if sigma > 0:
        mu_near = actor(obs + sigma * th.randn_like(obs), deterministic=True)
        spatial = (mu - mu_near).pow(2).sum(dim=1).mean()
    else:
        spatial = th.zeros((), dtype=mu.dtype)
    return temporal, spatial, magnitude


if TYPE_CHECKING:  # the mixin is always mixed into SAC or TQC, which share SAC's members
    _OffPolicy = SAC
else:
    _OffPolicy = object


class CapsMixin(_OffPolicy):
    """CAPS smoothness penalties on an off-policy actor (module docstring).

    Mixed in before stable-baselines3's SAC or sb3-contrib's TQC
    (``class CapsSAC(CapsMixin, SAC)``), which give the ``_critic_loss`` and
    ``_actor_value`` hooks below.

    Parameters
    ----------
    caps_temporal, caps_spatial, caps_magnitude : float
        Weights of the three penalties (>= 0; 0 turns a term off).
    caps_sigma : float
        Standard deviation of the observation perturbation of the spatial term, in
        the units the policy sees (normalised observations under ``VecNormalize``).
    *args, **kwargs
        The algorithm's own arguments.
    """

    def __init__(self, *args, caps_temporal: float = 0.0, caps_spatial: float = 0.0,
                 caps_magnitude: float = 0.0, caps_sigma: float = 0.05, **kwargs):
        for name, value in (("caps_temporal", caps_temporal), ("caps_spatial", caps_spatial),
                            ("caps_magnitude", caps_magnitude), ("caps_sigma", caps_sigma)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} {value!r}: must be a finite number >= 0")
        self.caps_temporal = float(caps_temporal)
        self.caps_spatial = float(caps_spatial)
        self.caps_magnitude = float(caps_magnitude)
        self.caps_sigma = float(caps_sigma)
        super().__init__(*args, **kwargs)

    def _critic_loss(self, replay_data, ent_coef, discounts, batch_size: int) -> th.Tensor:
        """The critics' loss on a replay batch (the algorithm's target)."""
        raise NotImplementedError

    def _actor_value(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """The critics' value (B, 1) of the actor's actions, which the actor maximises."""
        raise NotImplementedError

    @property
    def smoothing(self) -> bool:
        """Whether any penalty is on."""
        return (self.caps_temporal > 0 or self.caps_magnitude > 0
                or (self.caps_spatial > 0 and self.caps_sigma > 0))

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        """The algorithm's update (SB3 2.x ``SAC.train``'s loop) with the penalties added."""
        if not self.smoothing:
            super().train(gradient_steps, batch_size)
            return
        self.policy.set_training_mode(True)
        optimizers = [self.actor.optimizer, self.critic.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers += [self.ent_coef_optimizer]
        self._update_learning_rate(optimizers)

        assert self.replay_buffer is not None  # SAC's _setup_model made it
        ent_coef_losses, ent_coefs, actor_losses, critic_losses = [], [], [], []
        terms = []
        for gradient_step in range(gradient_steps):
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)
            discounts = (replay_data.discounts if replay_data.discounts is not None
                         else self.gamma)
            if self.use_sde:
                self.actor.reset_noise()
            actions_pi, log_prob = self.actor.action_log_prob(replay_data.observations)
            log_prob = log_prob.reshape(-1, 1)

            ent_coef_loss = None
            if self.ent_coef_optimizer is not None and self.log_ent_coef is not None:
                ent_coef = th.exp(self.log_ent_coef.detach())
                ent_coef_loss = -(self.log_ent_coef
                                  * (log_prob + float(self.target_entropy)).detach()).mean()
                ent_coef_losses.append(ent_coef_loss.item())
            else:
                ent_coef = self.ent_coef_tensor
            ent_coefs.append(ent_coef.item())
            if ent_coef_loss is not None and self.ent_coef_optimizer is not None:
                self.ent_coef_optimizer.zero_grad()
                ent_coef_loss.backward()
                self.ent_coef_optimizer.step()

            critic_loss = self._critic_loss(replay_data, ent_coef, discounts, batch_size)
            critic_losses.append(critic_loss.item())
            self.critic.optimizer.zero_grad()
            critic_loss.backward()
            self.critic.optimizer.step()

            actor_loss = (ent_coef * log_prob
                          - self._actor_value(replay_data.observations, actions_pi)).mean()
            temporal, spatial, magnitude = smoothness_terms(
                self.actor, replay_data.observations, replay_data.next_observations,
                self.caps_sigma if self.caps_spatial > 0 else 0.0)
            actor_loss = actor_loss + self.caps_temporal * temporal \
                + self.caps_spatial * spatial + self.caps_magnitude * magnitude
            terms.append((temporal.item(), spatial.item(), magnitude.item()))
            actor_losses.append(actor_loss.item())
            self.actor.optimizer.zero_grad()
            actor_loss.backward()
            self.actor.optimizer.step()

            if gradient_step % self.target_update_interval == 0:
                polyak_update(self.critic.parameters(), self.critic_target.parameters(),
                              self.tau)
                polyak_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)

        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/ent_coef", np.mean(ent_coefs))
        self.logger.record("train/actor_loss", np.mean(actor_losses))
        self.logger.record("train/critic_loss", np.mean(critic_losses))
        mean_terms = np.mean(terms, axis=0)
        self.logger.record("train/caps_temporal", mean_terms[0])
        self.logger.record("train/caps_spatial", mean_terms[1])
        self.logger.record("train/caps_magnitude", mean_terms[2])
        if ent_coef_losses:
            self.logger.record("train/ent_coef_loss", np.mean(ent_coef_losses))


def signature_with(base, extra=CAPS_DEFAULTS) -> inspect.Signature:
    """``base.__init__``'s signature with the keyword-only ``(name, default)`` pairs ``extra``.

    train.py and the algorithm table check a config's keys against the signature of the
    class it trains; a subclass taking ``*args, **kwargs`` on to ``base`` sets this as its
    ``__init__.__signature__``. By default ``extra`` is the smoothness keywords.
    """
    params = inspect.signature(base.__init__).parameters.values()
    return inspect.signature(base.__init__).replace(parameters=[
        *params, *(inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default)
                   for name, default in extra)])


class CapsSAC(CapsMixin, SAC):
    """stable-baselines3's SAC with the CAPS penalties of :class:`CapsMixin`."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)

    __init__.__signature__ = signature_with(SAC)  # type: ignore[attr-defined]

    def _critic_loss(self, replay_data, ent_coef, discounts, batch_size: int) -> th.Tensor:
        """SAC's clipped double-Q target and the mean squared error of each critic."""
        with th.no_grad():
            next_actions, next_log_prob = self.actor.action_log_prob(
                replay_data.next_observations)
            next_q = th.cat(self.critic_target(replay_data.next_observations, next_actions),
                            dim=1)
            next_q, _ = th.min(next_q, dim=1, keepdim=True)
            next_q = next_q - ent_coef * next_log_prob.reshape(-1, 1)
            target_q = replay_data.rewards + (1 - replay_data.dones) * discounts * next_q
        current_q = self.critic(replay_data.observations, replay_data.actions)
        return 0.5 * sum(F.mse_loss(q, target_q) for q in current_q)  # type: ignore[return-value]

    def _actor_value(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """The smallest of the critics' Q of the actor's action."""
        q_pi = th.cat(self.critic(obs, actions), dim=1)
        min_q_pi, _ = th.min(q_pi, dim=1, keepdim=True)
        return min_q_pi


_TQC_CLASS: list = []


def caps_tqc_class():
    """:class:`CapsTQC`, sb3-contrib's TQC with the CAPS penalties (made on first call).

    Raises
    ------
    ImportError
        When sb3-contrib is not installed, with the pip command that installs it.
    """
    if _TQC_CLASS:
        return _TQC_CLASS[0]
    try:
        from sb3_contrib import TQC
        from sb3_contrib.common.utils import quantile_huber_loss
    except ImportError as exc:
        tqc = ALGORITHMS["tqc"]
        raise ImportError(f"--algo tqc needs {tqc.requirement}: {tqc.install()}") from exc

    class CapsTQC(CapsMixin, TQC):  # type: ignore[misc]  # mypy sees CapsMixin as SAC
        """sb3-contrib's TQC with the CAPS penalties of :class:`CapsMixin`."""

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)

        __init__.__signature__ = signature_with(TQC)

        def _critic_loss(self, replay_data, ent_coef, discounts, batch_size: int
                         ) -> th.Tensor:
            """TQC's truncated target and its quantile Huber loss.

            All nets' quantiles at the next state, sorted, the top
            ``top_quantiles_to_drop_per_net`` per net dropped.
            """
            with th.no_grad():
                next_actions, next_log_prob = self.actor.action_log_prob(
                    replay_data.next_observations)
                next_quantiles = self.critic_target(replay_data.next_observations,
                                                    next_actions)
                critic: Any = self.critic  # TQC's quantile critics
                n_target = (critic.quantiles_total
                            - self.top_quantiles_to_drop_per_net * critic.n_critics)
                next_quantiles, _ = th.sort(next_quantiles.reshape(batch_size, -1))
                next_quantiles = next_quantiles[:, :n_target]
                target = next_quantiles - ent_coef * next_log_prob.reshape(-1, 1)
                target = replay_data.rewards + (1 - replay_data.dones) * discounts * target
                target.unsqueeze_(dim=1)
            current = self.critic(replay_data.observations, replay_data.actions)
            return quantile_huber_loss(current, target, sum_over_quantiles=False)

        def _actor_value(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
            """The mean over nets and quantiles of the actor's action."""
            return self.critic(obs, actions).mean(dim=2).mean(dim=1, keepdim=True)

    CapsTQC.__qualname__ = "CapsTQC"
    CapsTQC.__module__ = __name__
    _TQC_CLASS.append(CapsTQC)
    return CapsTQC


def __getattr__(name: str):
    """``CapsTQC`` on first use (:func:`caps_tqc_class`), as the algorithm table names it."""
    if name == "CapsTQC":
        return caps_tqc_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
