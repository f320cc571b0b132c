"""Candidate task changes of issue 12 as a stable-baselines3 VecEnvWrapper.

Exploratory code for the ablation only (not part of the package). The wrapper sits
directly on ``tether_gym_agents.training.vec_env.TetherSB3VecEnv`` (before VecMonitor and
VecNormalize) and recomputes the reward from the env's ``info`` (true state, not the
noisy observation), changes the observation and, optionally, the action.

Reward, with e_i = theta_i - theta_d, e_i' = theta_i' - theta_d',
c = mean(e_i^2) + 0.1 mean(e_i'^2) (as in v0):

    r = (1 - W_add) * r_track * (1 - p_mult) + sum_k w_k (1 - q_k)       in [0, 1]

* r_track: "v0"  1 / (1 + c / 0.05^2)
           "log" clip(-log10(max(sqrt(c), 1e-4)) / 4, 0, 1)   (R1: pays down to 1e-4 rad)
           "mix" 0.5 "v0" + 0.5 "log" (added after the first runs: "log" alone pays too
                 little between 1e-1 and 1e-2 rad)
* p_mult = 0.05 mean(a^2) + 0.05 mean(min(1, acc_ratio^2)) [+ the terms below that are
  "mult"]: effort and harsh accelerations (v0 weights).
* slack term q_s = mean(clip(1 - T^_min / 0.5, 0, 1)^2), weight 0.2:
  "mult" inside p_mult (v0), "add" as an additive term (R3: does not scale with r_track).
* length term, weight 0.2:
  "v0"    q_l = mean(min(1, ((l - l_nom) / 0.5)^2)) (saturating)
  "huber" q_l = mean(ph(x) / ph(ln 10)), x = ln(l / l_nom), ph(x) = sqrt(1 + (x/0.2)^2) - 1
          (R2: gradient everywhere; ln(l/l_nom) in [ln 0.1, ln 3] inside the length bounds,
          so q_l <= ~1 and is clipped to 1 only outside the documented bounds)
  placed "mult" (inside p_mult) or "add".
W_add is the sum of the additive weights.

Observation (O1): appends e_i, e_i' (from the observed, possibly noisy, theta and
theta') and ln(l_i / l_nom).
Action (A1, "incr"): the policy outputs a rate of change of the command:
cmd <- clip(cmd + k a, -1, 1); cmd is appended to the observation and initialised
from the observed reel rate at reset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnvWrapper

LN10 = math.log(10.0)


@dataclass(frozen=True)
class Design:
    track: str = "log"          # "v0" | "log" | "mix"
    slack: str = "add"          # "mult" | "add"
    length: str = "huber"       # "v0" | "huber"
    length_place: str = "add"   # "mult" | "add"
    obs_err: bool = True
    action: str = "direct"      # "direct" | "incr"
    incr_gain: float = 0.25
    w_slack: float = 0.2
    w_length: float = 0.2
    w_effort: float = 0.05
    w_accel: float = 0.05
    huber_delta: float = 0.2


def _pseudo_huber(x, delta):
    return np.sqrt(1.0 + (x / delta) ** 2) - 1.0


class TaskWrapper(VecEnvWrapper):
    """Reward / observation / action changes of a :class:`Design` (see module docstring)."""

    def __init__(self, venv, design: Design):
        self.design = design
        cfg = venv.config
        self.n = cfg.n_tethers
        self.l_nom = np.asarray(cfg.initial_lengths, dtype=float)
        self.max_rate = float(cfg.max_reel_rate)
        self.acc_ref = float(cfg.accel_reference)
        base = venv.observation_space
        extra = (3 * self.n if design.obs_err else 0) + (self.n if design.action == "incr" else 0)
        low = np.concatenate([base.low, np.full(extra, -np.inf, dtype=np.float32)])
        high = np.concatenate([base.high, np.full(extra, np.inf, dtype=np.float32)])
        obs_space = spaces.Box(low, high, dtype=np.float32)
        super().__init__(venv, observation_space=obs_space, action_space=venv.action_space)
        self.cmd = np.zeros((venv.num_envs, self.n))
        self._actions = None
        n = self.n
        self._sl = {"theta": slice(2, 2 + n), "dtheta": slice(2 + n, 2 + 2 * n),
                    "length": slice(2 + 2 * n, 2 + 3 * n), "dlength": slice(2 + 3 * n, 2 + 4 * n),
                    "ref": 2 + 4 * n, "dref": 3 + 4 * n}
        self._h_norm = float(_pseudo_huber(LN10, design.huber_delta))

    @property
    def config(self):
        return self.venv.config

    # --------------------------------------------------------------- obs
    def _augment(self, obs: np.ndarray, cmd: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        parts = [obs]
        s = self._sl
        if self.design.obs_err:
            e = obs[:, s["theta"]] - obs[:, [s["ref"]]]
            de = obs[:, s["dtheta"]] - obs[:, [s["dref"]]]
            ll = np.log(np.maximum(obs[:, s["length"]], 1e-3) / self.l_nom)
            parts += [e, de, ll.astype(np.float32)]
        if self.design.action == "incr":
            parts.append(cmd.astype(np.float32))
        return np.concatenate(parts, axis=1)

    def _init_cmd(self, obs: np.ndarray, rows=None) -> None:
        dl = obs[:, self._sl["dlength"]] / self.max_rate
        if rows is None:
            self.cmd[:] = np.clip(dl, -1, 1)
        else:
            self.cmd[rows] = np.clip(dl[rows], -1, 1)

    def reset(self):
        obs = self.venv.reset()
        self._init_cmd(obs)
        return self._augment(obs, self.cmd)

    # ------------------------------------------------------------ action
    def step_async(self, actions):
        a = np.clip(np.asarray(actions, dtype=float), -1.0, 1.0)
        if self.design.action == "incr":
            self.cmd = np.clip(self.cmd + self.design.incr_gain * a, -1.0, 1.0)
            cmd = self.cmd.copy()
        else:
            cmd = a
            self.cmd = a.copy()
        self._last_cmd = cmd
        self.venv.step_async(cmd.astype(np.float32))

    # ------------------------------------------------------------ reward
    def reward(self, info: dict, cmd: np.ndarray) -> tuple[float, dict]:
        d = self.design
        e = np.asarray(info["theta"]) - info["theta_ref"]
        de = np.asarray(info["dtheta"]) - info["dtheta_ref"]
        c = float(np.mean(e * e) + 0.1 * np.mean(de * de))
        if d.track == "v0":
            track = 1.0 / (1.0 + c / 0.05 ** 2)
        else:
            rms = math.sqrt(c) if math.isfinite(c) else 1e9
            track = min(1.0, max(0.0, -math.log10(max(rms, 1e-4)) / 4.0))
            if d.track == "mix":
                track = 0.5 * track + 0.5 / (1.0 + c / 0.05 ** 2)
        effort = float(np.mean(cmd * cmd))
        acc = float(np.mean(np.minimum(1.0, (np.asarray(info["reel_accel"]) / self.acc_ref) ** 2)))
        tmin = np.asarray(info["tension_min"])
        q_slack = float(np.mean(np.clip(1.0 - tmin / 0.5, 0.0, 1.0) ** 2))
        length = np.asarray(info["length"])
        if d.length == "v0":
            q_len = float(np.mean(np.minimum(1.0, ((length - self.l_nom) / 0.5) ** 2)))
        else:
            x = np.log(np.maximum(length, 1e-6) / self.l_nom)
            q_len = float(np.mean(np.minimum(1.0, _pseudo_huber(x, d.huber_delta) / self._h_norm)))
        p_mult = d.w_effort * effort + d.w_accel * acc
        w_add = 0.0
        add = 0.0
        if d.slack == "mult":
            p_mult += d.w_slack * q_slack
        else:
            w_add += d.w_slack
            add += d.w_slack * (1.0 - q_slack)
        if d.length_place == "mult":
            p_mult += d.w_length * q_len
        else:
            w_add += d.w_length
            add += d.w_length * (1.0 - q_len)
        r = (1.0 - w_add) * track * (1.0 - p_mult) + add
        if info.get("failure") == "nonfinite" or not math.isfinite(r):
            r = 0.0
        return r, {"c": c}

    def step_wait(self):
        obs, _, dones, infos = self.venv.step_wait()
        cmd = self._last_cmd
        rewards = np.zeros(self.num_envs, dtype=np.float32)
        for i, info in enumerate(infos):
            r, extra = self.reward(info, cmd[i])
            rewards[i] = r
            info["sq_err"] = extra["c"]
        if dones.any():
            rows = np.flatnonzero(dones)
            for i in rows:
                term = infos[i]["terminal_observation"]
                infos[i]["terminal_observation"] = self._augment(term[None], cmd[i:i + 1])[0]
            self._init_cmd(obs, rows)
        return self._augment(obs, self.cmd), rewards, dones, infos


# --------------------------------------------------------------------------------------
DESIGNS: dict[str, tuple[Design, dict]] = {}
"""variant name -> (Design or None for the plain v0 env, PPO overrides)."""

FULL = Design()
FULL_PPO = {"policy_kwargs": {"net_arch": [64, 64], "log_std_init": -3.5}}


def register_variants():
    from dataclasses import replace

    v = {
        "v0": (None, {}),                                               # control: v0 as shipped
        "full": (FULL, FULL_PPO),
        "full-R1": (replace(FULL, track="v0"), FULL_PPO),               # v0 tracking reward
        "full-R2": (replace(FULL, length="v0", length_place="mult"), FULL_PPO),  # v0 length term
        "full-R3": (replace(FULL, slack="mult"), FULL_PPO),             # slack inside r_track
        "full-O1": (replace(FULL, obs_err=False), FULL_PPO),            # no e, e', ln l in obs
        "full-R1+mix": (replace(FULL, track="mix"), FULL_PPO),      # wide + log tracking
        "full-X1": (FULL, {"policy_kwargs": {"net_arch": [64, 64], "log_std_init": -2.0}}),
        "full+A1": (replace(FULL, action="incr"), FULL_PPO),            # reel-rate increments
        "full+A1+mix": (replace(FULL, action="incr", track="mix"), FULL_PPO),  # A1, wide + log
        "full+A1-R1": (replace(FULL, action="incr", track="v0"), FULL_PPO),    # A1, Lorentzian
        "full+gSDE": (FULL, {"use_sde": True, "sde_sample_freq": 8,
                             "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -3.5}}),
    }
    DESIGNS.update(v)
    return DESIGNS


register_variants()
