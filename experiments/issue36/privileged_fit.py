"""Would observing e and the masses make mpc's labels easier to fit? (issue 36 probe)

Fits the distilled students' network (256 x 256 tanh, symlog error features S = 1e-4
rad, 40 epochs of Adam, batch 2048, seed 0: ``train.py distill``'s fit) on parts 0, 2,
.., 38 of set A of the shared mpc dataset, twice: on the observation alone and on the
observation closed by e and the mass fractions (what the env appends with
``observe_params=True``; taken from each pair's episode record). Prints each fit's
loss and its mean squared error on parts 40 .. 46 (held out). One core, about 65 s per
fit; docs/distillation.md quotes the result.

    python experiments/issue36/privileged_fit.py [--data runs/distill_data]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def load(paths, privileged: bool) -> tuple[np.ndarray, np.ndarray]:
    """Observations (closed by e and M_i when ``privileged``) and mpc's labels."""
    xs, ys = [], []
    for path in paths:
        d = np.load(path)
        obs = d["obs"]
        if privileged:  # each pair's episode, by its number, in the episode records' order
            numbers = sorted(set(d["episode"].tolist()))
            row = np.searchsorted(numbers, d["episode"])
            masses = d["episode_masses"][row]
            obs = np.concatenate([obs, d["episode_eccentricity"][row][:, None],
                                  masses / masses.sum(axis=1, keepdims=True)], axis=1)
        xs.append(obs.astype(np.float32))
        ys.append(d["labels"])
    return np.concatenate(xs), np.concatenate(ys)


def fit(privileged: bool, data_dir: str) -> str:
    import gymnasium as gym
    import torch

    import tether_gym
    from tether_gym_agents.training import dagger

    torch.set_num_threads(1)
    train = [f"{data_dir}/part_{k}/{dagger.DATA_FILE}" for k in range(0, 40, 2)]
    test = [f"{data_dir}/part_{k}/{dagger.DATA_FILE}" for k in range(40, 48, 2)]
    x, y = load(train, privileged)
    x_test, y_test = load(test, privileged)
    settings = dagger.DaggerSettings(iterations=0, epochs=40, batch_size=2048, seed=0,
                                     symlog_scale=1e-4, check_episodes=0)
    env = gym.make(tether_gym.ENV_ID, **{**dagger.training_env_kwargs(),
                                         "observe_params": privileged})
    assert env.observation_space.shape[0] == x.shape[1]
    policy = dagger.make_student(env, settings)
    data = dagger.Dataset.empty(x.shape[1], y.shape[1])
    data.obs, data.labels = x, y
    norm = dagger.normalization(dagger.student_inputs(settings, x, y.shape[1]))
    t0 = time.perf_counter()
    loss = dagger.fit_student(policy, data, norm, settings, torch.Generator().manual_seed(0))
    with torch.no_grad():
        inputs = torch.as_tensor(norm.apply(dagger.student_inputs(settings, x_test,
                                                                  y.shape[1])))
        pred = np.clip(dagger.deterministic_action(policy, inputs).numpy(), -1.0, 1.0)
    err = pred - y_test
    return (f"| {'obs + e, M_i' if privileged else 'obs'} | {len(x)} | {len(x_test)} | "
            f"{loss:.3e} | {np.mean(err**2):.3e} | {np.sqrt(np.mean(err**2)):.3e} | "
            f"{time.perf_counter() - t0:.0f} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default="runs/distill_data",
                   help="the shared dataset's folder (experiments/issue36/make_data.sh)")
    args = p.parse_args(argv)
    print("| student sees | fit pairs | held-out pairs | fit loss | held-out MSE | "
          "held-out RMS | fit [s] |")
    print("|---|---|---|---|---|---|---|")
    for privileged in (False, True):
        print(fit(privileged, args.data), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
