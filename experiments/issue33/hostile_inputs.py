"""The hostile inputs of the sweep, surface by surface (:func:`all_inputs`).

Each :class:`Input` is a command (argv for a subprocess; ``{py}``, ``{repo}``, ``{tmp}``
(the input's own temporary folder) and ``{fix}`` (the fixture cache) are filled in), what
it must do (``expect``), an optional ``setup`` that crafts files in ``tmp`` before the run
and an optional ``check`` that looks for harm after it (a message when harm was done).

expect: ``invalid`` must be refused; ``valid`` must run (exit 0); ``warn`` must run and
warn; ``any`` may run or be refused, but neither with a traceback, a hang nor harm.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import textwrap
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import fixtures as fx
import numpy as np
import yaml

ENV_ID = "tether_gym/TetherLibration-v1"
TRAIN = ["{py}", "{repo}/train.py"]
EVAL = ["{py}", "{repo}/evaluate.py"]
FILES = ["{py}", "-m", "tether_gym_agents.files"]
TINY = [*fx.TINY_TRAIN, "--checkpoint-freq", "64", "--out", "{tmp}/run"]
CONFIG_ARGS = ["--no-progress", "--eval-episodes", "1", "--out", "{tmp}/run"]
"""train.py options of the --config inputs: every other setting comes from the file (its
n_timesteps 64, n_envs 1, eval_freq and checkpoint_freq 64)."""
ETINY = ["--suite", "paper", "--seeds", "1", "--no-plots", "--out", "{tmp}/ev"]
NAN = float("nan")
INF = float("inf")


@dataclass
class Input:
    id: str
    surface: str
    argv: list[str]
    expect: str
    input: str
    setup: Callable[[Path, Path], None] | None = None
    check: Callable[[Path, Path], str | None] | None = None
    names: str | None = None
    """A path (template) the refusal should name (the file given); reported, not classed."""


def _lib(body: str) -> list[str]:
    """``python -c`` running ``body``; a TypeError/ValueError is the library's clear refusal
    (printed as one line, exit 2), anything else escapes as a traceback."""
    code = ("import sys, warnings\n"
            "warnings.simplefilter('default')\n"
            "try:\n" + textwrap.indent(textwrap.dedent(body), "    ") +
            "\nexcept (TypeError, ValueError) as exc:\n"
            "    print(f'{type(exc).__name__}: {exc}', file=sys.stderr)\n"
            "    sys.exit(2)\n")
    return ["{py}", "-c", code]


# --------------------------------------------------------------------------- #
# train.py options
def train_cli() -> list[Input]:
    s = "train_cli"
    bad = [
        ("algo.bogus", ["--algo", "bogus"]), ("algo.empty", ["--algo", ""]),
        ("algo.upper", ["--algo", "PPO"]),
        ("n_envs.zero", ["--n-envs", "0"]), ("n_envs.neg", ["--n-envs", "-1"]),
        ("n_envs.huge", ["--n-envs", "1000000000"]), ("n_envs.float", ["--n-envs", "1e9"]),
        ("n_envs.text", ["--n-envs", "abc"]),
        ("timesteps.zero", ["--timesteps", "0"]), ("timesteps.neg", ["--timesteps", "-5"]),
        ("timesteps.huge", ["--timesteps", str(10 ** 30)]),
        ("timesteps.nan", ["--timesteps", "nan"]),
        ("seed.neg", ["--seed", "-1"]), ("seed.2p31", ["--seed", str(2 ** 31)]),
        ("seed.2p64", ["--seed", str(2 ** 64)]), ("seed.text", ["--seed", "x"]),
        ("eval_freq.zero", ["--eval-freq", "0"]), ("eval_freq.neg", ["--eval-freq", "-1"]),
        ("eval_episodes.zero", ["--eval-episodes", "0"]),
        ("eval_episodes.huge", ["--eval-episodes", "1000000000"]),
        ("checkpoint_freq.zero", ["--checkpoint-freq", "0"]),
        ("checkpoint_freq.neg", ["--checkpoint-freq", "-64"]),
        ("torch_threads.zero", ["--torch-threads", "0"]),
        ("torch_threads.huge", ["--torch-threads", "100000"]),
        ("env_id.bogus", ["--env-id", "tether_gym/Nope-v9"]),
        ("env_id.empty", ["--env-id", ""]),
        ("env_kwargs.unknown", ["--env-kwargs", "bogus=1"]),
        ("env_kwargs.nan", ["--env-kwargs", "eccentricity=float('nan')"]),
        ("env_kwargs.nan_name", ["--env-kwargs", "eccentricity=nan"]),
        ("env_kwargs.ecc_1.5", ["--env-kwargs", "eccentricity=1.5"]),
        ("env_kwargs.masses_text", ["--env-kwargs", "masses=abc"]),
        ("env_kwargs.masses_len", ["--env-kwargs", "masses=(1,)"]),
        ("env_kwargs.n_bodies0", ["--env-kwargs", "n_bodies=0"]),
        ("env_kwargs.n_bodies_huge", ["--env-kwargs", "n_bodies=100000"]),
        ("env_kwargs.code", ["--env-kwargs", "eccentricity=__import__('os').getpid()"]),
        ("env_kwargs.no_eq", ["--env-kwargs", "eccentricity"]),
        ("env_kwargs.eq_only", ["--env-kwargs", "="]),
        ("env_kwargs.dup", ["--env-kwargs", "eccentricity=0.1", "eccentricity=0.2"]),
        ("env_kwargs.big_tuple", ["--env-kwargs", "masses=(" + "1," * 50000 + ")"]),
        ("env_kwargs.deep", ["--env-kwargs", "masses=" + "(" * 5000 + ")" * 5000]),
        ("env_kwargs.render", ["--env-kwargs", "render_mode='human'"]),
        ("out.empty", ["--out", ""]), ("out.devnull", ["--out", "/dev/null"]),
        ("out.proc", ["--out", "/proc/issue33/run"]),
        ("verbose.text", ["--verbose", "loud"]),
        ("unknown_flag", ["--learning-rate", "1"]),
        ("resume.no_run", ["--resume"]),
        ("config.missing", ["--config", "{tmp}/missing.yml"]),
        ("config.dir", ["--config", "{tmp}"]),
        ("seeds.zero", ["--seeds", "0"]), ("seeds.neg", ["--seeds", "-1"]),
        ("seeds.huge", ["--seeds", "1000000000", "--ray-address", "127.0.0.1:1"]),
        ("ray.garbage", ["--seeds", "2", "--ray-address", "garbage"]),
        ("ray.port", ["--seeds", "2", "--ray-address", "127.0.0.1:99999"]),
        ("ray.closed", ["--seeds", "2", "--ray-address", "127.0.0.1:1"]),
        ("ray.unreachable", ["--seeds", "2", "--ray-address", "10.255.255.1:6379"]),
        ("ray.no_seeds", ["--ray-address", "garbage"]),
        ("sweep.missing", ["--sweep", "{tmp}/missing.yml"]),
    ]
    either = {"env_kwargs.dup", "env_kwargs.render"}
    out = [Input(f"train.{i}", s, [*TRAIN, *TINY, *a], "any" if i in either else "invalid",
                 " ".join(a)) for i, a in bad]

    def file_out(tmp, fix):
        fx.write(tmp / "afile", "x")

    out.append(Input("train.out.file", s, [*TRAIN, *TINY, "--out", "{tmp}/afile"], "invalid",
                     "--out EXISTING_FILE", setup=file_out))
    out += [Input(f"train.valid.{a}", s, [*TRAIN, "--algo", a, *TINY], "valid",
                  f"--algo {a} (tiny)") for a in ("ppo", "sac", "td3", "tqc")]
    out.append(Input("train.valid.env_kwargs", s,
                     [*TRAIN, *TINY, "--env-kwargs", "eccentricity=0.3", "masses=(1,2)"],
                     "valid", "--env-kwargs eccentricity=0.3 masses=(1,2)"))
    return out


# --------------------------------------------------------------------------- #
# train.py --config YAML
def _base_config(algo: str = "ppo") -> dict:
    block = {"policy": "MlpPolicy", "n_envs": 1, "n_timesteps": 64,
             "normalize": {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0},
             "policy_kwargs": {"net_arch": [16, 16]},
             "env_kwargs": {"increment_gain": 0.5}}
    if algo == "ppo":
        block.update(n_steps=64, batch_size=32, n_epochs=1, learning_rate=3e-4, gamma=0.99)
    else:
        block.update(buffer_size=1000, learning_starts=16, batch_size=16, learning_rate=3e-4,
                     gamma=0.99, train_freq=1, gradient_steps=1)
    return {ENV_ID: block, "default": {"eval_freq": 64, "checkpoint_freq": 64}}


def _config_input(iid, desc, expect, algo="ppo", change=None, text=None, setup_file=None):
    def setup(tmp, fix):
        path = tmp / "cfg.yml"
        if setup_file is not None:
            setup_file(path, fix)
            return
        if text is not None:
            fx.write(path, text() if callable(text) else text)
            return
        cfg = _base_config(algo)
        change(cfg[ENV_ID], cfg)
        fx.write(path, yaml.safe_dump(cfg, sort_keys=False))

    return Input(f"config.{iid}", "train_config",
                 [*TRAIN, "--algo", algo, *CONFIG_ARGS, "--config", "{tmp}/cfg.yml"], expect,
                 desc,
                 setup=setup, names="{tmp}/cfg.yml")


def _set(key, value):
    def change(block, cfg):
        node = block
        parts = key.split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return change


def _alias_bomb(where: str, depth: int = 12) -> str:
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    for i in range(1, depth):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]")
    bomb = "\n".join("  " + ln for ln in lines)
    return f"{where}:\n{bomb}\n"


def train_config() -> list[Input]:
    out = []
    values = [
        ("n_envs.zero", "n_envs", 0), ("n_envs.huge", "n_envs", 1000000000),
        ("n_envs.text", "n_envs", "abc"), ("n_envs.nan", "n_envs", NAN),
        ("n_envs.float", "n_envs", 2.5), ("n_envs.bool", "n_envs", True),
        ("n_timesteps.nan", "n_timesteps", NAN), ("n_timesteps.neg", "n_timesteps", -1),
        ("lr.huge", "learning_rate", 1e308), ("lr.neg", "learning_rate", -1.0),
        ("lr.nan", "learning_rate", NAN), ("lr.inf", "learning_rate", INF),
        ("lr.text", "learning_rate", "abc"), ("lr.list", "learning_rate", [1, 2]),
        ("batch.zero", "batch_size", 0), ("batch.gt_rollout", "batch_size", 100000),
        ("batch.nan", "batch_size", NAN),
        ("n_epochs.huge", "n_epochs", 1000000000), ("n_epochs.zero", "n_epochs", 0),
        ("n_steps.zero", "n_steps", 0), ("n_steps.huge", "n_steps", 10 ** 12),
        ("gamma.2", "gamma", 2.0), ("gamma.nan", "gamma", NAN), ("gamma.neg", "gamma", -0.5),
        ("gae_lambda.1.5", "gae_lambda", 1.5), ("clip_range.neg", "clip_range", -0.2),
        ("ent_coef.nan", "ent_coef", NAN), ("vf_coef.inf", "vf_coef", INF),
        ("max_grad_norm.neg", "max_grad_norm", -1.0),
        ("policy.cnn", "policy", "CnnPolicy"), ("policy.bogus", "policy", "os.system"),
        ("policy.int", "policy", 3),
        ("net_arch.huge", "policy_kwargs.net_arch", [1000000000]),
        ("net_arch.neg", "policy_kwargs.net_arch", [-4]),
        ("net_arch.text", "policy_kwargs.net_arch", "abc"),
        ("log_std.nan", "policy_kwargs.log_std_init", NAN),
        ("log_std.huge", "policy_kwargs.log_std_init", 1e308),
        ("activation.code", "policy_kwargs.activation_fn", "os.system"),
        ("activation.bogus", "policy_kwargs.activation_fn", "NoSuchAct"),
        ("policy_kwargs.unknown", "policy_kwargs.bogus", 1),
        ("policy_kwargs.list", "policy_kwargs", [1, 2]),
        ("normalize.text", "normalize", "yes"), ("normalize.clip_neg", "normalize.clip_obs", -1.0),
        ("normalize.clip_nan", "normalize.clip_obs", NAN),
        ("normalize.unknown", "normalize.bogus", 1), ("normalize.obs_int", "normalize.norm_obs", 3),
        ("env_kwargs.list", "env_kwargs", [1, 2]), ("env_kwargs.unknown", "env_kwargs.bogus", 1),
        ("env_kwargs.ecc5", "env_kwargs.eccentricity", 5.0),
        ("env_kwargs.ecc_nan", "env_kwargs.eccentricity", NAN),
        ("env_kwargs.masses_neg", "env_kwargs.masses", [-1.0, 2.0]),
        ("rollout_buffer.unknown", "rollout_buffer_kwargs", {"bogus": 1}),
        ("unknown_key", "bogus_key", 1), ("device.bogus", "device", "nope:0"),
        ("eval_freq.zero", "eval_freq", 0), ("checkpoint_freq.neg", "checkpoint_freq", -1),
        ("seed.text", "seed", "abc"), ("verbose.huge", "verbose", 10 ** 9),
    ]
    either = {"verbose.huge"}
    out += [_config_input(i, f"{k}: {v!r}", "any" if i in either else "invalid",
                          change=_set(k, v)) for i, k, v in values]
    sac = [
        ("sac.buffer.huge", "buffer_size", 10 ** 12), ("sac.buffer.zero", "buffer_size", 0),
        ("sac.batch.gt_buffer", "batch_size", 5000),
        ("sac.replay.unknown", "replay_buffer_kwargs", {"bogus": 1}),
        ("sac.n_critics.huge", "policy_kwargs.n_critics", 1000000),
        ("sac.tau.2", "tau", 2.0), ("sac.learning_starts.neg", "learning_starts", -1),
        ("sac.train_freq.text", "train_freq", "abc"),
        ("sac.gradient_steps.huge", "gradient_steps", 10 ** 9),
        ("sac.ent_coef.text", "ent_coef", "auto_abc"),
        ("sac.n_steps.huge", "n_steps", 10 ** 9),
    ]
    out += [_config_input(i, f"(sac) {k}: {v!r}", "invalid", algo="sac", change=_set(k, v))
            for i, k, v in sac]
    # SAC, TD3 and TQC take n_steps (n-step returns, stable-baselines3 >= 2.6): in range,
    # a valid value
    out.append(_config_input("sac.n_steps", "(sac) n_steps: 64", "valid", algo="sac",
                             change=_set("n_steps", 64)))
    out.append(_config_input("td3.n_critics.huge", "(td3) policy_kwargs.n_critics: 1000000",
                             "invalid", algo="td3",
                             change=_set("policy_kwargs.n_critics", 1000000)))
    base = yaml.safe_dump(_base_config(), sort_keys=False)
    raw = [
        ("empty", "empty file", ""), ("null", "null", "null\n"),
        ("list", "top-level list", "[1, 2]\n"),
        ("scalar", "top-level scalar", "5\n"),
        ("flat", "keys at top level, no env block", "n_envs: 1\nn_steps: 64\n"),
        ("block_scalar", "env block is a scalar", f"{ENV_ID}: 5\n"),
        ("block_list", "env block is a list", f"{ENV_ID}: [1, 2]\n"),
        ("default_list", "default block is a list",
         base.replace("default:\n", "default: [1]\nunused:\n")),
        ("python_tag", "!!python/object/apply:os.system",
         base + "bad: !!python/object/apply:os.system ['echo PWNED > pwned']\n"),
        ("yaml_error", "unbalanced bracket", base + "bad: [1, 2\n"),
        ("tabs", "tab indentation", f"{ENV_ID}:\n\tn_envs: 1\n"),
        ("nan_key", "a .nan key", base + ".nan: 1\n"),
        ("alias_bomb_top", "alias bomb (10^12 nodes) beside the blocks",
         base + _alias_bomb("bomb")),
        ("alias_bomb_env", "alias bomb in env_kwargs",
         f"{ENV_ID}:\n  policy: MlpPolicy\n  n_envs: 1\n  env_kwargs:\n"
         + textwrap.indent(_alias_bomb("obs_bias"), "    ")),
        ("alias_single", "one anchor and one alias", base + "x: &x 1\ny: *x\n"),
        ("deep_list", "50k nested [", "[" * 50000 + "]" * 50000 + "\n"),
        ("deep_map", "20k nested {a:", "{a: " * 20000 + "1" + "}" * 20000 + "\n"),
        ("long_line", "one 20 MB line", lambda: "x: " + "a" * 20_000_000 + "\n"),
        ("many_keys", "16 MB of keys",
         lambda: "".join(f"k{i}: {i}\n" for i in range(1_000_000))),
        ("nul_bytes", "NUL bytes", base + "\x00\x00\x00"),
    ]
    out += [_config_input(i, d, "any" if i == "nan_key" else "invalid", text=t)
            for i, d, t in raw]

    def binary(path, fix):
        fx.write(path, bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8)))

    def utf16(path, fix):
        fx.write(path, base.encode("utf-16"))

    def fifo(path, fix):
        fx.replace_with_fifo(path)

    def zero(path, fix):
        fx.replace_with_link(path, "/dev/zero")

    def urandom(path, fix):
        fx.replace_with_link(path, "/dev/urandom")

    def dirpath(path, fix):
        path.mkdir()

    def unreadable(path, fix):
        fx.write(path, base)
        path.chmod(0)

    for i, d, f in [("binary", "4 kB of random bytes", binary), ("utf16", "UTF-16 file", utf16),
                    ("fifo", "a FIFO", fifo), ("dev_zero", "symlink to /dev/zero", zero),
                    ("dev_urandom", "symlink to /dev/urandom", urandom),
                    ("directory", "a directory", dirpath)]:
        out.append(_config_input(i, d, "any" if i == "utf16" else "invalid", setup_file=f))
    if os.geteuid() != 0:
        out.append(_config_input("unreadable", "mode 000", "invalid", setup_file=unreadable))
    out.append(_config_input("valid", "the base tiny config", "valid", change=lambda b, c: None))
    out.append(_config_input("valid.sac", "the base tiny SAC config", "valid", algo="sac",
                             change=lambda b, c: None))
    return out


# --------------------------------------------------------------------------- #
# train.py --sweep FILE
def sweep_files() -> list[Input]:
    def inp(iid, desc, text):
        def setup(tmp, fix):
            fx.write(tmp / "sweep.yml", text)
        return Input(f"sweepfile.{iid}", "train_sweep",
                     [*TRAIN, *TINY, "--sweep", "{tmp}/sweep.yml", "--ray-address",
                      "127.0.0.1:1"], "invalid", desc, setup=setup, names="{tmp}/sweep.yml")

    good = "search: grid\nseeds_per_trial: 2\nparams:\n  learning_rate: [1.0e-4, 3.0e-4]\n"
    return [
        inp("unknown", "unknown top key", good + "bogus: 1\n"),
        inp("search", "search: bogus", good.replace("grid", "bogus")),
        inp("seeds1", "seeds_per_trial: 1", good.replace("2", "1", 1)),
        inp("seeds_huge", "seeds_per_trial: 1e9", good.replace("2", "1000000000", 1)),
        inp("params_list", "params is a list", "search: grid\nparams: [1, 2]\n"),
        inp("param_unknown", "param bogus_key", "search: grid\nparams:\n  bogus_key: [1, 2]\n"),
        inp("param_nan", "learning_rate: [.nan]",
            "search: grid\nparams:\n  learning_rate: [.nan, .inf]\n"),
        inp("grid_huge", "grid of 10^12 trials", "search: grid\nparams:\n" + "".join(
            f"  policy_kwargs.k{i}: [{', '.join(str(j) for j in range(10))}]\n"
            for i in range(12))),
        inp("num_samples_huge", "random, num_samples 1e12",
            "search: random\nnum_samples: 1000000000000\n"
            "params:\n  gamma: {uniform: [0.9, 0.99]}\n"),
        inp("uniform_bad", "uniform: [1, 0]",
            "search: random\nparams:\n  gamma: {uniform: [1.0, 0.0]}\n"),
        inp("alias_bomb", "alias bomb", good + _alias_bomb("bomb")),
        inp("deep", "50k nested [", "[" * 50000 + "]" * 50000),
    ]


# --------------------------------------------------------------------------- #
# evaluate.py options
def _seeds_folder(tmp: Path, fix: Path) -> None:
    """``tmp/seeds/seed_0``: a copy of the tiny PPO run (for curves); ``tmp/empty``."""
    (tmp / "seeds").mkdir()
    shutil.copytree(fix / "run_ppo", tmp / "seeds" / "seed_0", symlinks=True)
    (tmp / "empty").mkdir()


def evaluate_cli() -> list[Input]:
    s = "evaluate_cli"
    bad = [
        ("policy.bogus", ["bogus"]), ("policy.empty", [""]),
        ("policy.dev_zero", ["/dev/zero"]), ("policy.dev_null", ["/dev/null"]),
        ("policy.missing_path", ["{tmp}/nope"]), ("policy.handover_bogus", ["handover:bogus"]),
        ("policy.handover_empty", ["handover:"]), ("policy.handover2", ["handover:handover:ppo"]),
        ("policy.dup", ["smc", "smc"]), ("policy.dots", [".."]),
        ("policy.long", ["p" * 100000]),
        ("seeds.zero", ["zero", "--seeds", "0"]), ("seeds.neg", ["zero", "--seeds", "-1"]),
        ("seeds.huge", ["zero", "--seeds", "1001"]), ("seeds.text", ["zero", "--seeds", "abc"]),
        ("seed.neg", ["zero", "--seed", "-1"]), ("seed.2p64", ["zero", "--seed", str(2 ** 64)]),
        ("seed.nan", ["zero", "--seed", "nan"]),
        ("out.empty", ["zero", "--out", ""]), ("out.devnull", ["zero", "--out", "/dev/null"]),
        ("out.proc", ["zero", "--out", "/proc/issue33/ev"]),
        ("threads.zero", ["zero", "--torch-threads", "0"]),
        ("threads.huge", ["zero", "--torch-threads", "1000000"]),
        ("env_kwargs.unknown", ["zero", "--env-kwargs", "bogus=1"]),
        ("env_kwargs.n_bodies0", ["zero", "--env-kwargs", "n_bodies=0"]),
        ("env_kwargs.nan", ["zero", "--env-kwargs", "eccentricity=float('nan')"]),
        ("env_kwargs.masses_text", ["zero", "--env-kwargs", "masses=abc"]),
        ("env_kwargs.masses_len", ["smc", "--env-kwargs", "masses=(1,2,3)"]),
        ("env_kwargs.masses_zero", ["smc", "--env-kwargs", "masses=(0,0)"]),
        ("env_kwargs.code", ["zero", "--env-kwargs", "eccentricity=(lambda: 1)()"]),
        ("env_kwargs.inf_orbits", ["zero", "--env-kwargs", "orbits_per_episode=float('inf')"]),
        ("suite.bogus", ["zero", "--suite", "bogus"]),
        ("suite.missing", ["zero", "--suite", "{tmp}/missing.yml"]),
        ("suite.dev_zero", ["zero", "--suite", "/dev/zero"]),
        ("paper.no_out", ["paper"]),
        ("paper.orbits_neg", ["paper", "--out", "{tmp}/p", "--orbits", "-1"]),
        ("paper.orbits_nan", ["paper", "--out", "{tmp}/p", "--orbits", "nan"]),
        ("paper.out_empty", ["paper", "--out", ""]),
        ("curves.missing", ["curves", "{tmp}/nope", "--out", "{tmp}/c"]),
        ("curves.no_out", ["curves", "{tmp}"]),
        ("curves.rms_nan", ["curves", "{tmp}/seeds", "--out", "{tmp}/c", "--rms", "nan"]),
        ("curves.success_2", ["curves", "{tmp}/seeds", "--out", "{tmp}/c", "--success", "2"]),
        ("curves.seeds0", ["curves", "{tmp}/seeds", "--out", "{tmp}/c", "--seeds", "0"]),
        ("curves.empty_folder", ["curves", "{tmp}/empty", "--out", "{tmp}/c"]),
        ("unknown_command_flag", ["zero", "--bogus"]),
    ]
    out = []
    tiny = {"--suite": "paper", "--seeds": "1", "--out": "{tmp}/ev"}
    for i, a in bad:
        argv = [*EVAL, *a]
        if a[0] not in ("paper", "curves"):  # tiny options, unless the input sets one
            for key, value in tiny.items():
                if key not in a:
                    argv += [key, value]
            argv.append("--no-plots")
        out.append(Input(f"eval.{i}", s, argv, "any" if i in ("policy.dup",) else "invalid",
                         " ".join(a), setup=_seeds_folder))

    def existing(tmp, fix):
        _seeds_folder(tmp, fix)
        fx.write(tmp / "afile", "keep me\n")

    def keep(tmp, fix):
        return None if (tmp / "afile").read_text() == "keep me\n" else "overwrote the file"

    out.append(Input("eval.out.file", s, [*EVAL, "zero", "--suite", "paper", "--seeds", "1",
                                          "--no-plots", "--out", "{tmp}/afile"],
                     "invalid", "--out EXISTING_FILE", setup=existing, check=keep))
    out.append(Input("eval.paper.out_file", s, [*EVAL, "paper", "--out", "{tmp}/afile",
                                                "--orbits", "1", "--quick"],
                     "invalid", "paper --out EXISTING_FILE", setup=existing, check=keep))
    out.append(Input("eval.curves.out_file", s, [*EVAL, "curves", "{tmp}/seeds", "--out",
                                                 "{tmp}/afile"],
                     "invalid", "curves --out EXISTING_FILE", setup=existing, check=keep))
    out += [Input("eval.valid.zero", s, [*EVAL, "zero", *ETINY], "valid", "zero (tiny)"),
            Input("eval.valid.smc", s, [*EVAL, "smc", *ETINY], "valid", "smc (tiny)"),
            Input("eval.valid.agent", s, [*EVAL, "{fix}/run_ppo", *ETINY], "valid",
                  "a run folder (tiny)")]
    return out


# --------------------------------------------------------------------------- #
# evaluate.py --suite FILE
def suite_files() -> list[Input]:
    def scenario(**kw):
        sc = {"name": "s1", "description": "test", "env_kwargs": {}}
        sc.update(kw)
        return sc

    def inp(iid, desc, data=None, text=None, expect="invalid", setup_file=None, policy="smc"):
        def setup(tmp, fix):
            path = tmp / "suite.yml"
            if setup_file is not None:
                setup_file(path)
            elif text is not None:
                fx.write(path, text() if callable(text) else text)
            else:
                fx.write(path, yaml.safe_dump(data() if callable(data) else data,
                                              sort_keys=False))
        return Input(f"suite.{iid}", "suite_yaml",
                     [*EVAL, policy, "--suite", "{tmp}/suite.yml", "--seeds", "1",
                      "--no-plots", "--out", "{tmp}/ev"], expect, desc, setup=setup,
                     names="{tmp}/suite.yml")

    good = {"scenarios": [scenario()]}
    good_text = yaml.safe_dump(good, sort_keys=False)
    nom = lambda **k: {"scenarios": [scenario(nominal=k)]}  # noqa: E731
    out = [
        inp("scenarios.missing", "no scenarios key", {"other": 1}),
        inp("scenarios.empty", "scenarios: []", {"scenarios": []}),
        inp("scenarios.dict", "scenarios is a dict", {"scenarios": {"a": 1}}),
        inp("scenarios.str", "scenarios is a string", {"scenarios": "abc"}),
        inp("scenario.int", "a scenario is an int", {"scenarios": [1]}),
        inp("name.missing", "no name", {"scenarios": [{"description": "x", "env_kwargs": {}}]}),
        inp("name.int", "name: 5", {"scenarios": [scenario(name=5)]}),
        inp("name.empty", "name: ''", {"scenarios": [scenario(name="")]}),
        inp("name.dup", "two scenarios named s1", {"scenarios": [scenario(), scenario()]}),
        inp("name.path", "name: ../../x", {"scenarios": [scenario(name="../../x")]},
            expect="any"),
        inp("desc.list", "description: [1]", {"scenarios": [scenario(description=[1])]}),
        inp("desc.huge", "a 5 MB description",
            lambda: {"scenarios": [scenario(description="d" * 5_000_000)]}),
        inp("unknown.top", "unknown top key", {**good, "bogus": 1}),
        inp("unknown.scenario", "unknown scenario key", {"scenarios": [scenario(bogus=1)]}),
        inp("env_kwargs.list", "env_kwargs: [1]", {"scenarios": [scenario(env_kwargs=[1])]}),
        inp("env_kwargs.unknown", "env_kwargs: {bogus: 1}",
            {"scenarios": [scenario(env_kwargs={"bogus": 1})]}),
        inp("env_kwargs.ecc_nan", "eccentricity: .nan",
            {"scenarios": [scenario(env_kwargs={"eccentricity": NAN})]}),
        inp("env_kwargs.ecc_inf", "eccentricity: .inf",
            {"scenarios": [scenario(env_kwargs={"eccentricity": INF})]}),
        inp("env_kwargs.n_bodies_big", "n_bodies: 100000",
            {"scenarios": [scenario(env_kwargs={"n_bodies": 100000})]}),
        inp("env_kwargs.orbits_huge", "orbits_per_episode: 1e12",
            {"scenarios": [scenario(env_kwargs={"orbits_per_episode": 1e12})]}),
        inp("nominal.masses_text", "nominal masses: abc", nom(masses="abc")),
        inp("nominal.masses_zero", "nominal masses: [0, 0]", nom(masses=[0, 0])),
        inp("nominal.masses_neg", "nominal masses: [-1, 2]", nom(masses=[-1, 2])),
        inp("nominal.masses_len", "nominal masses: [1]", nom(masses=[1])),
        inp("nominal.masses_nan", "nominal masses: [.nan, 1]", nom(masses=[NAN, 1])),
        inp("nominal.ecc_1.5", "nominal eccentricity: 1.5", nom(eccentricity=1.5)),
        inp("nominal.ecc_neg", "nominal eccentricity: -0.1", nom(eccentricity=-0.1)),
        inp("nominal.unknown", "nominal bogus: 1", nom(bogus=1)),
        inp("nominal.tau0", "nominal reel_time_constant: 0", nom(reel_time_constant=0)),
        inp("nominal.accel_neg", "nominal accel_limit: -1", nom(accel_limit=-1)),
        inp("nominal.list", "nominal: [1]", {"scenarios": [scenario(nominal=[1])]}),
        inp("nominal.masses_mpc", "nominal masses [0, 0] for mpc", nom(masses=[0, 0]),
            policy="mpc"),
        inp("python_tag", "!!python/object/apply", text=good_text
            + "x: !!python/object/apply:os.system ['echo PWNED > pwned']\n"),
        inp("alias_bomb.desc", "alias bomb in a description", text=(
            "scenarios:\n  - name: s1\n    env_kwargs: {}\n    description:\n"
            + textwrap.indent(_alias_bomb("d"), "      "))),
        inp("alias_bomb.env", "alias bomb in env_kwargs", text=(
            "scenarios:\n  - name: s1\n    description: x\n    env_kwargs:\n"
            + textwrap.indent(_alias_bomb("obs_bias"), "      "))),
        inp("deep", "50k nested [", text="[" * 50000 + "]" * 50000),
        inp("huge", "an 11 MB suite (220k scenarios)", text=lambda: "scenarios:\n" + "".join(
            f"  - {{name: s{i}, description: x, env_kwargs: {{}}}}\n" for i in range(220000))),
        inp("yaml_error", "unbalanced bracket", text="scenarios: [\n"),
        inp("empty", "empty file", text=""),
        inp("binary", "random bytes", setup_file=lambda p: fx.write(
            p, bytes(np.random.default_rng(1).integers(0, 256, 4096, dtype=np.uint8)))),
        inp("fifo", "a FIFO", setup_file=fx.replace_with_fifo),
        inp("dev_zero", "symlink to /dev/zero", setup_file=lambda p: fx.replace_with_link(
            p, "/dev/zero")),
        inp("directory", "a directory", setup_file=lambda p: p.mkdir()),
        inp("valid", "one plain scenario", good, expect="valid"),
        inp("valid.nominal", "nominal masses [1.2, 1.6]", nom(masses=[1.2, 1.6]), expect="valid"),
    ]
    return out


# --------------------------------------------------------------------------- #
# agent folders: agent.json and policy.safetensors
def _agent_input(iid, desc, edit=None, weights=None, restamp=True, files=None,
                 expect="invalid", src="run_ppo/final_agent", check=None):
    def setup(tmp, fix):
        agent = fx.copy_tree(fix / src, tmp / "agent")
        if edit is not None:
            data = fx.load_json(agent / "agent.json")
            data = edit(data) or data
            fx.dump_json(agent / "agent.json", data)
        if weights is not None:
            tensors = fx.load_weights(agent / "policy.safetensors")
            tensors = weights(tensors)
            fx.save_weights(agent / "policy.safetensors", tensors)
            if restamp:
                fx.restamp(agent)
        if files is not None:
            files(agent, tmp, fix)

    surface = "weights_file" if (weights is not None or iid.startswith("w.")) else "agent_folder"
    return Input(f"agent.{iid}", surface, [*EVAL, "{tmp}/agent", *ETINY], expect, desc,
                 setup=setup, check=check, names="{tmp}/agent")


def _path(data, dotted, value=None, delete=False):
    node = data
    parts = dotted.split(".")
    for p in parts[:-1]:
        node = node[int(p)] if isinstance(node, list) else node[p]
    last = int(parts[-1]) if isinstance(node, list) else parts[-1]
    if delete:
        del node[last]
    else:
        node[last] = value
    return data


def agent_folders() -> list[Input]:
    out = []
    keys = ["format", "format_version", "algo", "policy_class", "policy_kwargs",
            "observation_space", "action_space", "obs_normalization", "weights", "env",
            "training", "hybrid", "features", "versions"]
    wrong = {"format": 7, "format_version": "1", "algo": ["ppo"], "policy_class": 3,
             "policy_kwargs": "abc", "observation_space": [20], "action_space": "Box",
             "obs_normalization": [1, 2], "weights": "policy.safetensors", "env": "tether",
             "training": 5, "hybrid": 3.5, "features": [1], "versions": "latest"}
    # keys whose absence is tolerated by design (informational / optional)
    optional = {"training", "versions", "hybrid", "features", "obs_normalization"}
    for k in keys:
        out.append(_agent_input(f"missing.{k}", f"agent.json without {k!r}",
                                edit=lambda d, k=k: _path(d, k, delete=True),
                                expect="any" if k in optional else "invalid"))
        out.append(_agent_input(f"type.{k}", f"{k}: {wrong[k]!r}",
                                edit=lambda d, k=k: _path(d, k, wrong[k]),
                                expect="any" if k in ("training", "versions") else "invalid"))
    out.append(_agent_input("extra.top", "an extra top-level key",
                            edit=lambda d: _path(d, "bogus", 1), expect="any"))
    values = [
        ("algo.bogus", "algo", "bogus"), ("algo.sac_in_ppo", "algo", "sac"),
        ("format.other", "format", "other-format"), ("format_version.2", "format_version", 2),
        ("format_version.huge", "format_version", 1e308),
        ("format_version.nan", "format_version", NAN),
        ("policy_class.bogus", "policy_class", "os.system"),
        ("net_arch.huge", "policy_kwargs.net_arch", [1000000000, 1000000000]),
        ("net_arch.neg", "policy_kwargs.net_arch", [-1]),
        ("net_arch.text", "policy_kwargs.net_arch", "abc"),
        ("log_std.nan", "policy_kwargs.log_std_init", NAN),
        ("log_std.huge", "policy_kwargs.log_std_init", 1e308),
        ("activation.code", "policy_kwargs.activation_fn", "os.system"),
        ("activation.bogus", "policy_kwargs.activation_fn", "NoSuch"),
        ("extractor.code", "policy_kwargs.features_extractor_class", "subprocess.Popen"),
        ("policy_kwargs.unknown", "policy_kwargs.bogus", 1),
        ("obs.mean_nan", "obs_normalization.mean.0", NAN),
        ("obs.mean_huge", "obs_normalization.mean.0", 1e308),
        ("obs.mean_short", "obs_normalization.mean", [0.0, 0.0]),
        ("obs.mean_text", "obs_normalization.mean", "abc"),
        ("obs.var_neg", "obs_normalization.var.0", -1.0),
        ("obs.var_inf", "obs_normalization.var.0", INF),
        ("obs.count_neg", "obs_normalization.count", -1.0),
        ("obs.clip_neg", "obs_normalization.clip_obs", -1.0),
        ("obs.clip_nan", "obs_normalization.clip_obs", NAN),
        ("obs.eps_neg", "obs_normalization.epsilon", -1.0),
        ("obs_space.shape21", "observation_space.shape", [21]),
        ("obs_space.shape_neg", "observation_space.shape", [-1]),
        ("obs_space.shape_huge", "observation_space.shape", [10 ** 12]),
        ("obs_space.dtype", "observation_space.dtype", "object"),
        ("obs_space.low_nan", "observation_space.low.0", NAN),
        ("obs_space.type", "observation_space.type", "Discrete"),
        ("act_space.shape3", "action_space.shape", [3]),
        ("act_space.low_gt_high", "action_space.low", [2.0, 2.0]),
        ("act_space.high_inf", "action_space.high", ["inf", "inf"]),
        ("act_space.type", "action_space.type", "Discrete"),
        ("act_space.dtype", "action_space.dtype", "int8"),
        ("weights.file_up", "weights.file", "../outside/policy.safetensors"),
        ("weights.file_abs", "weights.file", "/etc/passwd"),
        ("weights.file_missing", "weights.file", "nope.safetensors"),
        ("weights.sha_bad", "weights.sha256", "0" * 64),
        ("weights.sha_int", "weights.sha256", 5),
        ("weights.module", "weights.module", "bogus"),
        ("weights.extra", "weights.bogus", 1),
        ("env.id_bogus", "env.id", "tether_gym/Nope-v0"),
        ("env.id_other", "env.id", "CartPole-v1"),
        ("env.kwargs_unknown", "env.kwargs.bogus", 1),
        ("env.kwargs_list", "env.kwargs", [1, 2]),
        ("env.n_bodies", "env.kwargs.n_bodies", 4),
        ("env.ecc_nan", "env.kwargs.eccentricity", NAN),
        ("hybrid.bogus", "hybrid", {"type": "bogus"}), ("hybrid.text", "hybrid", "bogus"),
        ("features.bogus", "features", {"type": "bogus"}),
        ("training.steps_nan", "training.num_timesteps", NAN),
    ]
    for i, k, v in values:
        out.append(_agent_input(i, f"{k}: {v!r}", edit=lambda d, k=k, v=v: _path(d, k, v),
                                expect="any" if i == "training.steps_nan" else "invalid"))

    def var0(d):
        d["obs_normalization"]["var"][0] = 0.0
        d["obs_normalization"]["epsilon"] = 0.0
    out.append(_agent_input("obs.var0_eps0", "var[0] 0 and epsilon 0", edit=var0))

    def outside_weights(agent, tmp, fix):
        shutil.copy(agent / "policy.safetensors", fx.write(tmp / "outside" / "x", "").parent
                    / "policy.safetensors")
    out.append(_agent_input("weights.file_up_exists", "weights.file ../outside/... (exists)",
                            edit=lambda d: _path(d, "weights.file",
                                                 "../outside/policy.safetensors"),
                            files=outside_weights))

    # agent.json as a file
    def aj(fn):
        return lambda agent, tmp, fix: fn(agent / "agent.json", tmp)
    for i, d, f in [
        ("json.not_json", "agent.json is not JSON", lambda p, t: fx.write(p, "not json {")),
        ("json.empty", "agent.json is empty", lambda p, t: fx.write(p, "")),
        ("json.list", "agent.json is a list", lambda p, t: fx.write(p, "[1, 2]")),
        ("json.nan", "agent.json is NaN", lambda p, t: fx.write(p, "NaN")),
        ("json.deep", "agent.json: 100k nested [",
         lambda p, t: fx.write(p, "[" * 100000 + "]" * 100000)),
        ("json.huge", "agent.json: 60 MB", lambda p, t: fx.write(
            p, '{"pad": "' + "x" * 60_000_000 + '"}')),
        ("json.binary", "agent.json: random bytes", lambda p, t: fx.write(
            p, bytes(np.random.default_rng(2).integers(0, 256, 4096, dtype=np.uint8)))),
        ("json.fifo", "agent.json is a FIFO", lambda p, t: fx.replace_with_fifo(p)),
        ("json.dev_zero", "agent.json -> /dev/zero",
         lambda p, t: fx.replace_with_link(p, "/dev/zero")),
        ("json.link_out", "agent.json -> a copy outside the folder", lambda p, t: (
            shutil.copy(p, fx.write(t / "outside" / "agent.json", "")), fx.replace_with_link(
                p, t / "outside" / "agent.json"))),
        ("json.dir", "agent.json is a directory", lambda p, t: (p.unlink(), p.mkdir())),
        ("json.missing", "no agent.json", lambda p, t: p.unlink()),
    ]:
        out.append(_agent_input(i, d, files=aj(f)))

    # the weights file
    def cast(dtype):
        return lambda t: {k: v.astype(dtype) for k, v in t.items()}

    def poke(value, key="action_net.weight"):
        def f(t):
            t[key] = t[key].copy()
            t[key].flat[0] = value
            return t
        return f

    def reshape(t):
        t["action_net.weight"] = np.zeros((3, 64), np.float32)
        return t

    def drop(t):
        del t["action_net.bias"]
        return t

    def extra(t):
        t["extra.tensor"] = np.zeros(3, np.float32)
        return t

    def big(t):
        t["action_net.weight"] = np.zeros((2, 64 * 4), np.float32)
        return t

    for i, d, f in [("w.int8", "weights cast to int8", cast(np.int8)),
                    ("w.bool", "weights cast to bool", cast(np.bool_)),
                    ("w.float16", "weights cast to float16", cast(np.float16)),
                    ("w.int64", "weights cast to int64", cast(np.int64)),
                    ("w.nan", "a NaN weight", poke(NAN)), ("w.inf", "an inf weight", poke(INF)),

                    ("w.log_std_nan", "log_std NaN", poke(NAN, "log_std")),
                    ("w.log_std_inf", "log_std inf", poke(INF, "log_std")),
                    ("w.shape", "action_net.weight of shape (3, 64)", reshape),
                    ("w.shape_wide", "action_net.weight of shape (2, 256)", big),
                    ("w.missing_tensor", "action_net.bias missing", drop),
                    ("w.extra_tensor", "an extra tensor", extra)]:
        out.append(_agent_input(i, d, weights=f))
    out.append(_agent_input("w.huge", "a 3e38 weight", weights=poke(np.float32(3e38)),
                            expect="any"))
    out.append(_agent_input("w.nan_stale_sha", "a NaN weight, sha256 not updated",
                            weights=poke(NAN), restamp=False))

    def wfile(fn, do_restamp=True):
        def files(agent, tmp, fix):
            fn(agent / "policy.safetensors", tmp, fix)
            if do_restamp and (agent / "policy.safetensors").is_file() \
                    and not (agent / "policy.safetensors").is_symlink():
                fx.restamp(agent)
        return files

    def truncate(p, t, f):
        data = p.read_bytes()
        p.write_bytes(data[: len(data) // 2])

    def header_huge(p, t, f):
        p.write_bytes((2 ** 60).to_bytes(8, "little") + b"{}")

    def header_bad(p, t, f):
        hdr = b'{"a": {"dtype": "F32", "shape": [1000000000000], "data_offsets": [0, 4]}}'
        p.write_bytes(len(hdr).to_bytes(8, "little") + hdr + b"\0" * 4)

    def header_code(p, t, f):
        hdr = json.dumps({"__metadata__": {"format": "pt"}, "x": {
            "dtype": "F32", "shape": [1], "data_offsets": [0, 4]}}).encode()
        p.write_bytes(len(hdr).to_bytes(8, "little") + hdr + b"\0" * 4)

    def swap_sac(p, t, f):
        shutil.copy(f / "run_sac" / "final_agent" / "policy.safetensors", p)

    def swap_sac_nostamp(p, t, f):
        shutil.copy(f / "run_sac" / "final_agent" / "policy.safetensors", p)

    def link_out(p, t, f):
        target = t / "outside" / "policy.safetensors"
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(p, target)
        fx.replace_with_link(p, target)

    def hardlink_out(p, t, f):
        target = t / "outside" / "policy.safetensors"
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(p, target)
        p.unlink()
        os.link(target, p)

    for i, d, f, rs in [
        ("w.truncated", "weights file cut in half", truncate, True),
        ("w.empty", "weights file empty", lambda p, t, f: p.write_bytes(b""), True),
        ("w.header_huge", "header length 2^60", header_huge, True),
        ("w.header_shape", "header: shape 1e12, 4 bytes", header_bad, True),
        ("w.header_foreign", "a valid file with other tensors", header_code, True),
        ("w.missing", "no policy.safetensors", lambda p, t, f: p.unlink(), False),
        ("w.fifo", "policy.safetensors is a FIFO", lambda p, t, f: fx.replace_with_fifo(p), False),
        ("w.dev_zero", "policy.safetensors -> /dev/zero",
         lambda p, t, f: fx.replace_with_link(p, "/dev/zero"), False),
        ("w.link_out", "policy.safetensors -> a copy outside", link_out, False),
        ("w.dir", "policy.safetensors is a directory", lambda p, t, f: (p.unlink(), p.mkdir()),
         False),
        ("w.swap_sac", "SAC's weights, sha256 updated", swap_sac, True),
        ("w.swap_sac_nostamp", "SAC's weights, sha256 stale", swap_sac_nostamp, False),
    ]:
        out.append(_agent_input(i, d, files=wfile(f, rs)))
    out.append(_agent_input("w.hardlink_out", "policy.safetensors hard-linked outside",
                            files=wfile(hardlink_out, False), expect="any"))
    out.append(_agent_input("folder.dev_zero_extra", "an extra file -> /dev/zero",
                            files=lambda a, t, f: fx.replace_with_link(a / "notes.bin",
                                                                       "/dev/zero"),
                            expect="any"))
    out.append(_agent_input("valid", "the unmodified agent", expect="valid"))
    out.append(_agent_input("valid.sac", "the unmodified SAC agent", expect="valid",
                            src="run_sac/final_agent"))
    return out


# --------------------------------------------------------------------------- #
# run folders: --resume, export, evaluate RUN, curves
def _run_input(iid, surface, argv, desc, mutate=None, expect="invalid", check=None,
               src="run_ppo", names="{tmp}/"):
    def setup(tmp, fix):
        fx.secret(tmp)
        run = fx.copy_tree(fix / src, tmp / "run")
        if mutate is not None:
            mutate(run, tmp, fix)
        fx.dump_json(tmp / "outside.json", fx.snapshot(tmp / "outside"))

    def checks(tmp, fix):
        before = fx.load_json(tmp / "outside.json")
        after = fx.snapshot(tmp / "outside")
        changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
        if changed:
            return f"changed outside the folders given: outside/{changed[0]}"
        return check(tmp, fix) if check is not None else None

    return Input(iid, surface, argv, expect, desc, setup=setup, check=checks, names=names)


RESUME = [*TRAIN, "--algo", "ppo", "--resume", *TINY]


def _no_secret(where: str):
    def check(tmp, fix):
        hits = fx.tree_contains(tmp / where, fx.SECRET)
        return f"secret copied into {where}/{hits[0]}" if hits else None
    return check


def _secret_intact(tmp, fix):
    p = tmp / "outside" / "secret.txt"
    if not p.is_file() or p.read_text() != fx.SECRET + "\n":
        return "the file outside the folder was modified"
    hits = fx.tree_contains(tmp / "run", fx.SECRET, but=p)
    return f"secret written into run/{hits[0]}" if hits else None


def run_folders() -> list[Input]:
    out = []

    def link(rel, target):
        return lambda run, tmp, fix: fx.replace_with_link(run / rel, target(tmp) if callable(
            target) else target)

    def fifo(rel):
        return lambda run, tmp, fix: fx.replace_with_fifo(run / rel)

    def write(rel, text):
        return lambda run, tmp, fix: fx.write(run / rel, text)

    def outside_copy(rel):
        def f(run, tmp, fix):
            target = tmp / "outside" / Path(rel).name
            shutil.copy(run / rel, target)
            fx.replace_with_link(run / rel, target)
        return f

    def info(key, value):
        def f(run, tmp, fix):
            d = fx.load_json(run / "train_info.json")
            d[key] = value
            fx.dump_json(run / "train_info.json", d)
        return f

    def npz_nan(rel):
        def f(run, tmp, fix):
            with np.load(run / rel) as z:
                d = {k: np.asarray(z[k]) for k in z.files}
            for k, v in d.items():
                if v.dtype.kind == "f" and v.size:
                    v = v.copy()
                    v.flat[0] = np.nan
                    d[k] = v
            np.savez(run / rel, **d)
        return f

    def hard_secret(rel):
        def f(run, tmp, fix):
            (run / rel).unlink()
            os.link(tmp / "outside" / "secret.txt", run / rel)
        return f

    resume_cases = [
        ("ckpt.fifo", "checkpoints/model_9999_steps.zip is a FIFO",
         fifo("checkpoints/model_9999_steps.zip")),
        ("ckpt.dev_zero", "checkpoints/model_9999_steps.zip -> /dev/zero",
         link("checkpoints/model_9999_steps.zip", "/dev/zero")),
        ("ckpt.link_out", "checkpoints/model_64_steps.zip -> outside copy",
         outside_copy("checkpoints/model_64_steps.zip")),
        ("ckpt.npz_nan", "checkpoint statistics with NaN",
         npz_nan("checkpoints/model_vecnormalize_64_steps.npz")),
        ("ckpt.npz_fifo", "checkpoint statistics a FIFO",
         fifo("checkpoints/model_vecnormalize_64_steps.npz")),
        ("final.link_out", "final_model.zip -> outside copy", outside_copy("final_model.zip")),
        ("final.dev_zero", "final_model.zip -> /dev/zero", link("final_model.zip", "/dev/zero")),
        ("final.fifo", "final_model.zip is a FIFO", fifo("final_model.zip")),
        ("final.garbage", "final_model.zip is not a zip", write("final_model.zip", "garbage")),
        ("vecnorm.link_out", "vecnormalize.npz -> outside copy", outside_copy("vecnormalize.npz")),
        ("vecnorm.dev_zero", "vecnormalize.npz -> /dev/zero",
         link("vecnormalize.npz", "/dev/zero")),
        ("vecnorm.nan", "vecnormalize.npz with NaN", npz_nan("vecnormalize.npz")),
        ("vecnorm.garbage", "vecnormalize.npz is not npz", write("vecnormalize.npz", "garbage")),
        ("config.alias_bomb", "run config.yml with an alias bomb",
         lambda run, tmp, fix: fx.write(run / "config.yml", (run / "config.yml").read_text()
                                        + _alias_bomb("bomb"))),
        ("config.fifo", "run config.yml is a FIFO", fifo("config.yml")),
        ("config.dev_zero", "run config.yml -> /dev/zero", link("config.yml", "/dev/zero")),
        ("config.python_tag", "run config.yml with a python tag",
         lambda run, tmp, fix: fx.write(run / "config.yml", (run / "config.yml").read_text()
                                        + "x: !!python/object/apply:os.system ['echo PWNED']\n")),
        ("config.n_envs_huge", "run config.yml n_envs: 1e9",
         lambda run, tmp, fix: fx.write(run / "config.yml", _replace_key(
             (run / "config.yml").read_text(), "n_envs", "1000000000"))),
        ("info.steps_nan", "train_info.json num_timesteps NaN", info("num_timesteps", NAN)),
        ("info.steps_text", "train_info.json num_timesteps 'abc'", info("num_timesteps", "abc")),
        ("info.steps_neg", "train_info.json num_timesteps -1", info("num_timesteps", -1)),
        ("info.fifo", "train_info.json is a FIFO", fifo("train_info.json")),
        ("info.dev_zero", "train_info.json -> /dev/zero", link("train_info.json", "/dev/zero")),
        ("eval.fifo", "eval/evaluations.npz is a FIFO", fifo("eval/evaluations.npz")),
        ("eval.dev_zero", "eval/evaluations.npz -> /dev/zero",
         link("eval/evaluations.npz", "/dev/zero")),
        ("eval.garbage", "eval/evaluations.npz is not npz", write("eval/evaluations.npz", "x")),
        ("command.link_secret", "command.txt -> outside secret",
         link("command.txt", lambda t: t / "outside" / "secret.txt")),
        ("command.fifo", "command.txt is a FIFO", fifo("command.txt")),
        ("command.hard_secret", "command.txt hard link of an outside secret",
         hard_secret("command.txt")),
        ("tb.link_out", "tb/ -> outside folder",
         link("tb", lambda t: (t / "outside").resolve())),
    ]
    maybe_unread = {"ckpt.link_out", "ckpt.npz_nan", "ckpt.npz_fifo", "config.n_envs_huge",
                    "info.steps_nan", "info.steps_text", "info.steps_neg", "info.fifo",
                    "info.dev_zero"}  # files resume may not need: must only not hang or harm
    # A saved model that does not load (not a zip, statistics not an npz or not finite) is
    # skipped with a warning and the run resumes from the newest one that loads: resume's
    # documented answer to a file truncated by a kill (agents/training/resume.py).
    skipped_with_warning = {"vecnorm.garbage", "vecnorm.nan", "eval.garbage"}
    # final_model.zip that is not a zip has no step count: it sorts after every checkpoint,
    # and the newest checkpoint loads, so it is never read.
    maybe_unread.add("final.garbage")
    for i, d, m in resume_cases:
        out.append(_run_input(f"resume.{i}", "run_resume", RESUME, f"--resume: {d}", m,
                              check=_secret_intact,
                              expect="any" if i in maybe_unread else
                              "warn" if i in skipped_with_warning else "invalid"))
    out.append(_run_input("resume.algo_mismatch", "run_resume",
                          [*TRAIN, "--algo", "sac", "--resume", *TINY],
                          "--resume --algo sac on a PPO run"))
    out.append(_run_input("resume.valid", "run_resume", RESUME, "--resume (tiny)",
                          expect="valid"))

    exp = [*FILES, "export", "{tmp}/run", "{tmp}/dest"]
    export_cases = [
        ("final_agent.link_out", "final_agent -> outside agent (secret in its agent.json)",
         _final_agent_out, "any"),
        ("weights.dev_zero", "final_agent/policy.safetensors -> /dev/zero",
         link("final_agent/policy.safetensors", "/dev/zero"), "any"),
        ("weights.fifo", "final_agent/policy.safetensors is a FIFO",
         fifo("final_agent/policy.safetensors"), "any"),
        ("command.link_secret", "command.txt -> outside secret",
         link("command.txt", lambda t: t / "outside" / "secret.txt"), "any"),
        ("command.hard_secret", "command.txt hard link of an outside secret",
         hard_secret("command.txt"), "invalid"),
        ("agent_json.hard_secret", "agent.json hard link of an outside secret",
         hard_secret("agent.json"), "invalid"),
        ("eval.fifo", "eval/evaluations.npz is a FIFO", fifo("eval/evaluations.npz"), "any"),
        ("dev_zero_extra", "an extra file -> /dev/zero", link("notes.bin", "/dev/zero"), "any"),
    ]
    for i, d, m, e in export_cases:
        out.append(_run_input(f"export.{i}", "run_export", exp, f"export: {d}", m, expect=e,
                              check=_no_secret("dest")))

    def dest_eval_link(run, tmp, fix):
        (tmp / "dest").mkdir()
        (tmp / "outside" / "evil").mkdir(parents=True)
        os.symlink(tmp / "outside" / "evil", tmp / "dest" / "eval")

    def outside_untouched(tmp, fix):
        evil = tmp / "outside" / "evil"
        return f"wrote into {evil}" if evil.is_dir() and any(evil.iterdir()) else None

    out.append(_run_input("export.dest_eval_link", "run_export", exp,
                          "export into DEST whose eval/ -> outside folder", dest_eval_link,
                          check=outside_untouched))

    def dest_file(run, tmp, fix):
        fx.write(tmp / "dest", "x")
    out.append(_run_input("export.dest_file", "run_export", exp, "export to DEST = a file",
                          dest_file))
    out.append(_run_input("export.dest_in_src", "run_export",
                          [*FILES, "export", "{tmp}/run", "{tmp}/run/inner"],
                          "export into a folder inside SRC", expect="any"))
    out.append(_run_input("export.dest_is_src", "run_export",
                          [*FILES, "export", "{tmp}/run", "{tmp}/run"], "export onto SRC"))
    out.append(_run_input("export.src_missing", "run_export",
                          [*FILES, "export", "{tmp}/nope", "{tmp}/dest"], "export: no SRC"))
    out.append(_run_input("export.src_dev_zero", "run_export",
                          [*FILES, "export", "/dev/zero", "{tmp}/dest"], "export: SRC /dev/zero"))
    out.append(_run_input("export.src_link", "run_export",
                          [*FILES, "export", "{tmp}/runlink", "{tmp}/dest"],
                          "export: SRC is a symlink to a run",
                          lambda run, tmp, fix: os.symlink(run, tmp / "runlink"), expect="any"))
    out.append(_run_input("export.convert_no_pickle", "run_export",
                          [*FILES, "convert", "{tmp}/run"], "convert without --allow-pickle"))
    out.append(_run_input("export.valid", "run_export", exp, "export (plain run)",
                          expect="valid", check=_no_secret("dest")))

    # evaluate.py RUN / seed folders / curves
    def seed_link(run, tmp, fix):
        (tmp / "seeds").mkdir()
        os.symlink(run, tmp / "seeds" / "seed_0")

    def seeds_copy(run, tmp, fix):
        (tmp / "seeds").mkdir()
        shutil.copytree(run, tmp / "seeds" / "seed_0", symlinks=True)

    def curves_zero(run, tmp, fix):
        seeds_copy(run, tmp, fix)
        fx.replace_with_link(tmp / "seeds/seed_0/checkpoints/agent_32_steps/policy.safetensors",
                             "/dev/zero")

    def curves_fifo(run, tmp, fix):
        seeds_copy(run, tmp, fix)
        fx.replace_with_fifo(tmp / "seeds/seed_0/checkpoints/agent_32_steps/agent.json")

    def curves_link_out(run, tmp, fix):
        seeds_copy(run, tmp, fix)
        fx.replace_with_link(tmp / "seeds/seed_0/checkpoints/agent_32_steps",
                             (fix / "run_ppo/checkpoints/agent_64_steps").resolve())

    def curves_info_nan(run, tmp, fix):
        seeds_copy(run, tmp, fix)
        p = tmp / "seeds/seed_0/train_info.json"
        d = fx.load_json(p)
        d["wall_time_s"] = NAN
        fx.dump_json(p, d)

    ev = [*ETINY]
    run_eval = [
        # A run folder's best agent (at its top) is the one evaluated: final_agent/ is
        # not read then; without a top agent it is, and a link out must be refused.
        ("final_agent.link_out", "RUN/final_agent -> another agent folder (top agent kept)",
         [*EVAL, "{tmp}/run", *ev], lambda run, tmp, fix: fx.replace_with_link(
             run / "final_agent", (fix / "run_sac/final_agent").resolve()), "any"),
        ("final_agent.link_out_read", "RUN/final_agent -> another agent folder, no top agent",
         [*EVAL, "{tmp}/run", *ev], _final_agent_read_out, "invalid"),
        ("agent_json.link_out", "RUN/agent.json -> outside copy", [*EVAL, "{tmp}/run", *ev],
         outside_copy("agent.json"), "any"),
        ("seed_link", "FOLDER/seed_0 -> a run folder", [*EVAL, "{tmp}/seeds", *ev], seed_link,
         "invalid"),
        ("empty_run", "a run folder with nothing to load", [*EVAL, "{tmp}/run", *ev],
         lambda run, tmp, fix: [p.unlink() for p in run.rglob("*") if p.is_file()
                                or p.is_symlink()], "invalid"),
        ("curves.dev_zero", "curves: checkpoint weights -> /dev/zero",
         [*EVAL, "curves", "{tmp}/seeds", "--suite", "paper", "--seeds", "1", "--out",
          "{tmp}/c"], curves_zero, "invalid"),
        ("curves.fifo", "curves: checkpoint agent.json a FIFO",
         [*EVAL, "curves", "{tmp}/seeds", "--suite", "paper", "--seeds", "1", "--out",
          "{tmp}/c"], curves_fifo, "invalid"),
        ("curves.link_out", "curves: checkpoint folder -> outside",
         [*EVAL, "curves", "{tmp}/seeds", "--suite", "paper", "--seeds", "1", "--out",
          "{tmp}/c"], curves_link_out, "invalid"),
        ("curves.info_nan", "curves: train_info wall_time_s NaN",
         [*EVAL, "curves", "{tmp}/seeds", "--suite", "paper", "--seeds", "1", "--out",
          "{tmp}/c"], curves_info_nan, "any"),
        ("valid", "evaluate RUN (tiny)", [*EVAL, "{tmp}/run", *ev], None, "valid"),
        ("curves.valid", "curves on one seed run",
         [*EVAL, "curves", "{tmp}/seeds", "--suite", "paper", "--seeds", "1", "--out",
          "{tmp}/c"], seeds_copy, "valid"),
    ]
    for i, d, argv, m, e in run_eval:
        out.append(_run_input(f"runeval.{i}", "run_evaluate", argv, d, m, expect=e))
    return out


def _final_agent_read_out(run: Path, tmp: Path, fix: Path) -> None:
    for name in ("agent.json", "policy.safetensors"):
        (run / name).unlink()
    fx.replace_with_link(run / "final_agent", (fix / "run_sac/final_agent").resolve())


def _final_agent_out(run: Path, tmp: Path, fix: Path) -> None:
    agent = shutil.copytree(run / "final_agent", tmp / "outside" / "agent")
    data = fx.load_json(agent / "agent.json")
    data["training"]["command"] = fx.SECRET
    fx.dump_json(agent / "agent.json", data)
    fx.replace_with_link(run / "final_agent", agent)


def _replace_key(text: str, key: str, value: str) -> str:
    lines = [f"{ln.split(':')[0]}: {value}" if ln.strip().startswith(f"{key}:") else ln
             for ln in text.splitlines()]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- #
# gym.make keyword arguments
def gym_make() -> list[Input]:
    body = ("import gymnasium as gym, numpy as np, tether_gym\n"
            f"env = gym.make({ENV_ID!r}, {{kw}})\n"
            "env.reset(seed=0)\n"
            "for _ in range(3):\n"
            "    env.step(np.zeros(env.action_space.shape, env.action_space.dtype))\n"
            "print('ran')\n")
    nan, inf = "float('nan')", "float('inf')"
    bad = [
        "n_bodies=1", "n_bodies=0", "n_bodies=2.5", "n_bodies='3'", "n_bodies=10**6",
        "n_bodies=True", f"eccentricity={nan}", f"eccentricity={inf}", "eccentricity=1.0",
        "eccentricity=-0.1", "eccentricity='0.2'", "eccentricity=[0.2]",
        "semi_latus_rectum=0", f"semi_latus_rectum={nan}", "semi_latus_rectum=-1e7",
        "mu=0", f"mu={inf}", "masses=(1,)", "masses=(0, 2)", "masses=(-1, 2)",
        f"masses=({nan}, 2)", "masses='ab'", "?masses=(1e308, 1e308)",
        "initial_lengths=(0, 0.5)", "initial_lengths=(1, 2, 3)", f"initial_lengths=({inf}, 1)",
        "total_tether_length=0", f"total_tether_length={nan}", "gravity='bogus'", "gravity=3",
        "accel_limit=-1", f"accel_limit={nan}", "?speed_limit=0", "reel_time_constant=-1",
        f"reel_time_constant={nan}", "?max_reel_rate=0", f"max_reel_rate={inf}",
        "action_mode='bogus'", "?action_mode=None", "increment_gain=-1",
        f"increment_gain={nan}", "?amplitude=-1", f"amplitude={nan}", "?frequency=0",
        f"frequency={inf}", f"initial_nu={nan}", f"initial_theta=({nan}, 0)",
        "?initial_theta=(2.0, 0)", "initial_theta=(0.1,)", "control_step=0",
        "control_step=-0.1", f"control_step={nan}", "physics_step=0", "physics_step=1.0",
        "orbits_per_episode=0", "orbits_per_episode=-1", f"orbits_per_episode={inf}",
        "?orbits_per_episode=1e12", "length_bounds=(1, 0)", "length_bounds=(0.1,)",
        f"length_bounds=(0, {nan})", "init_theta_range=-0.1", f"init_theta_range={nan}",
        "?init_theta_range=10", "init_dtheta_range=-1", "init_length_range=-1",
        "eccentricity_range=(0.5, 0.1)", "eccentricity_range=(0, 1.5)",
        f"eccentricity_range=(0, {nan})", "mass_range=-0.1", "mass_range=1.5",
        "obs_noise=-1", f"obs_noise={nan}", f"obs_bias={inf}", "disturbance=-1",
        f"disturbance={nan}", "observe_params='yes'", "observe_params=2",
        "reward_weights={'bogus': 1}", "reward_weights='abc'",
        f"reward_weights={{'safe_tension': {nan}}}", "render_mode='bogus'", "bogus=1",
        "eccentricity=0.2, eccentricty=0.3",
    ]
    out = [Input("gym." + re.sub(r"[^\w=.,()'\[\]{}:+-]", "", kw.lstrip("?")), "gym_make",
                 _lib(body.replace("{kw}", kw.lstrip("?"))),
                 "any" if kw.startswith("?") else "invalid", kw.lstrip("?")) for kw in bad]
    for j, kw in enumerate(["", "eccentricity=0.3", "n_bodies=4", "action_mode='rate'",
                            "masses=(1.5, 2.5)"]):
        out.append(Input(f"gym.valid{j}", "gym_make", _lib(body.replace("{kw}", kw)), "valid",
                         kw or "(defaults)"))
    return out


# --------------------------------------------------------------------------- #
# mpc's constructor and observations
def mpc() -> list[Input]:
    body = ("import gymnasium as gym, numpy as np, tether_gym\n"
            "from tether_gym_agents.baselines.mpc import ModelPredictiveController as M\n"
            f"env = gym.make({ENV_ID!r}, action_mode='rate', {{env}})\n"
            "obs, _ = env.reset(seed=0)\n"
            "ctl = M.for_env(env, {kw})\n"
            "obs = {obs}\n"
            "print('action', ctl.predict(obs)[0])\n")

    def inp(i, kw="", env="", obs="obs", expect="invalid", desc=None):
        desc = desc or ", ".join(x for x in (kw, env, obs if obs != "obs" else "") if x)
        small = [] if i == "valid" else [  # a short plan builds in 0.4 s instead of 20 s
            x for x in ("blocks=(1, 2)", "iterations=1") if x.split("=")[0] not in kw]
        kw = ", ".join([*small, kw] if kw else small)
        code = body.replace("{kw}", kw).replace("{env}", env).replace("{obs}", obs)
        return Input(f"mpc.{i}", "mpc", _lib(code), expect, desc)

    nan = "float('nan')"
    cases = [
        ("blocks.int", "blocks=5"), ("blocks.str", "blocks='abc'"), ("blocks.empty", "blocks=()"),
        ("blocks.zero", "blocks=(0,)"), ("blocks.float", "blocks=(1.5,)"),
        ("blocks.300", "blocks=(1,)*300"), ("blocks.huge", "blocks=(10**9,)"),
        ("blocks.bool", "blocks=(True,)"), ("blocks.dict", "blocks={1: 2}"),
        ("iter.zero", "iterations=0"), ("iter.huge", "iterations=10**9"),
        ("iter.float", "iterations=2.5"), ("iter.bool", "iterations=True"),
        ("weights.str", "weights='abc'"), ("weights.unknown", "weights={'bogus': 1}"),
        ("weights.nan", f"weights={{'rate': {nan}}}"), ("weights.neg", "weights={'rate': -1}"),
        ("weights.slack0", "weights={'slack': 0}"),
        ("weights.inf", "weights={'move': float('inf')}"),
        ("weights.text", "weights={'rate': 'x'}"),
        ("margins.10rad", "margins={'libration': 10}"),
        ("margins.nan", f"margins={{'libration': {nan}}}"),
        ("margins.neg", "margins={'length': -1}"), ("margins.str", "margins='x'"),
        ("margins.floor", "margins={'tension_floor': 100}"),
        ("nominal.masses0", "nominal={'masses': (0, 0)}"),
        ("nominal.masses_neg", "nominal={'masses': (-1, 2)}"),
        ("nominal.masses_len1", "nominal={'masses': (1,)}"),
        ("nominal.masses_len3", "nominal={'masses': (1, 2, 3)}"),
        ("nominal.masses_nan", f"nominal={{'masses': ({nan}, 2)}}"),
        ("nominal.ecc1.5", "nominal={'eccentricity': 1.5}"),
        ("nominal.ecc_nan", f"nominal={{'eccentricity': {nan}}}"),
        ("nominal.unknown", "nominal={'bogus': 1}"), ("nominal.str", "nominal='abc'"),
        ("nominal.tau0", "nominal={'reel_time_constant': 0}"),
        ("nominal.accel_neg", "nominal={'accel_limit': -1}"),
        ("unknown_kwarg", "bogus=1"),
    ]
    out = [inp(i, kw) for i, kw in cases]
    out += [
        inp("obs.nan", obs="np.full_like(obs, np.nan)", desc="all-NaN observation"),
        inp("obs.one_nan", obs="np.where(np.arange(obs.size) == 0, np.nan, obs)",
            desc="one NaN in the observation"),
        inp("obs.inf", obs="np.full_like(obs, np.inf)", desc="all-inf observation"),
        inp("obs.huge", obs="np.full_like(obs, 1e30)", desc="observation of 1e30",
            expect="any"),
        inp("obs.shape", obs="obs[:3]", desc="observation of the wrong length"),
        inp("obs.text", obs="'abc'", desc="observation 'abc'"),
        Input("mpc.env.increment", "mpc",
              _lib(body.replace("action_mode='rate', {env}", "action_mode='increment'")
                   .replace("{kw}", "blocks=(1, 2), iterations=1").replace("{obs}", "obs")),
              "invalid", "env in increment mode (not rate)"),
        inp("warn.ecc0.9", env="eccentricity=0.9", expect="warn", desc="env e = 0.9 (warns)"),
        inp("warn.n4", env="n_bodies=4", expect="warn", desc="N = 4 bodies (warns)"),
        inp("valid", expect="valid", desc="defaults"),
        inp("valid.blocks", kw="blocks=(1, 2, 4), iterations=1", expect="valid",
            desc="blocks=(1, 2, 4), iterations=1"),
    ]
    return out


# --------------------------------------------------------------------------- #
# an install without an optional dependency (the module shadowed by one that fails)
def missing_dependency() -> list[Input]:
    def shadow(*names):
        def setup(tmp, fix):
            for name in names:
                fx.write(tmp / "shadow" / name / "__init__.py",
                         f"raise ModuleNotFoundError(\"No module named '{name}'\", "
                         f"name={name!r})\n")
        return setup

    env = ["env", "PYTHONPATH={tmp}/shadow"]
    cases = [
        ("train.torch", ("torch",), [*TRAIN, *TINY], "invalid"),
        ("train.yaml", ("yaml",), [*TRAIN, *TINY], "invalid"),
        ("train.tqc", ("sb3_contrib",), [*TRAIN, "--algo", "tqc", *TINY], "invalid"),
        ("train.ray", ("ray",), [*TRAIN, *TINY, "--seeds", "2"], "invalid"),
        ("eval.default.torch", ("torch",), [*EVAL, *ETINY], "invalid"),
        ("eval.agent.torch", ("torch",), [*EVAL, "{fix}/run_ppo", *ETINY], "invalid"),
        ("eval.mpc.casadi", ("casadi",), [*EVAL, "mpc", *ETINY], "invalid"),
        ("eval.smc.torch", ("torch", "stable_baselines3"), [*EVAL, "smc", *ETINY], "any"),
        ("files.export.torch", ("torch",), [*FILES, "export", "{fix}/run_ppo", "{tmp}/d"],
         "any"),
    ]
    return [Input(f"nodep.{i}", "missing_dep", [*env, *argv], e,
                  f"{' '.join(mods)} not installed: {' '.join(argv[1:3])}".replace(
                      "{repo}/", ""), setup=shadow(*mods), names="pip install")
            for i, mods, argv, e in cases]


SURFACES = {"train_cli": train_cli, "train_config": train_config, "train_sweep": sweep_files,
            "evaluate_cli": evaluate_cli, "suite_yaml": suite_files,
            "agent_folder": agent_folders, "run_folder": run_folders, "gym_make": gym_make,
            "mpc": mpc, "missing_dep": missing_dependency}


def all_inputs() -> list[Input]:
    out = [x for make in SURFACES.values() for x in make()]
    ids = [x.id for x in out]
    dup = {i for i in ids if ids.count(i) > 1}
    if dup:
        raise AssertionError(f"duplicate input ids {sorted(dup)}")
    return out
