"""``train.py distill``: DAgger on mpc's labels (issue 36), checked through the command.

One tiny run (2 iterations x 1 episode of 0.05 orbit) is made in-process with
``train.py``'s ``main``; its files are checked against the mathematics: every label is
mpc's action on the recorded observation (a fresh controller replays the episode's
observations), the mixture executes the actor its draws pick, the saved agent is the
network on observations normalised with the dataset's statistics, ``evaluate.py`` scores
the folder, a second run with the same seed writes the same files, and bad arguments
are refused before any work.
"""

from __future__ import annotations

import contextlib
import io
import json
import re

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main as train_main
from tether_gym_agents.files import TrainedAgent
from tether_gym_agents.files.run_folder import ITERATION_LOG_FILE

pytest.importorskip("casadi")
torch = pytest.importorskip("torch")
load_file = pytest.importorskip("safetensors.torch").load_file

from tether_gym_agents.training import dagger  # noqa: E402

ORBITS = "0.05"
TINY = ["--iterations", "2", "--episodes", "1", "--epochs", "3", "--orbits", ORBITS,
        "--check-episodes", "1", "--net-arch", "32", "32"]


def _train(out, extra=()):
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = train_main(["distill", *TINY, *extra, "--out", str(out)])
    return code, stdout.getvalue()


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("dagger") / "seed_0"
    code, text = _train(out)
    assert code == 0, text
    data = dict(np.load(out / dagger.DATA_FILE))
    return out, text, data


def test_progress_lines_and_files(run):
    out, text, data = run
    lines = [line for line in text.splitlines() if line.startswith("iteration ")]
    assert [line.split()[1] for line in lines] == ["0", "1"]
    assert "(beta 1, expert acted 1.00)" in lines[0] and "(beta 0.5," in lines[1]
    log = json.loads((out / ITERATION_LOG_FILE).read_text())
    per_iteration = [int(np.sum(data["iteration"] == i)) for i in range(2)]
    assert [r["labels"] for r in log] == list(np.cumsum(per_iteration))
    assert f"{log[-1]['labels']} labels" in lines[1] and "labels/s" in lines[1]
    assert re.search(r"student alone: [01]/1 survived, median tracking RMS n/a", lines[1])
    for record in log:  # a checkpoint per iteration, its steps = the labels fitted on
        assert (out / "checkpoints" / f"agent_{record['labels']}_steps" / "agent.json").is_file()
    info = json.loads((out / "train_info.json").read_text())
    assert info["labels"] == len(data["obs"]) == log[-1]["labels"]
    assert "python evaluate.py" in text


def test_every_label_is_mpcs_action_on_the_observation(run):
    """A fresh mpc per episode, called on the recorded observations in order, gives the labels.

    Iteration 1's episode is flown partly by the student: the labels are still mpc's on
    what the mixture visited.
    """
    _, _, data = run
    base = dagger.training_env_kwargs(float(ORBITS))
    assert base["action_mode"] == "rate" and "increment_gain" not in base
    for k in range(len(data["episode_env_seed"])):
        kwargs = {key: v for key, v in base.items()
                  if key not in ("eccentricity_range", "mass_range")}
        kwargs["eccentricity"] = float(data["episode_eccentricity"][k])
        kwargs["masses"] = tuple(float(m) for m in data["episode_masses"][k])
        env = gym.make(tether_gym.ENV_ID, **kwargs)
        expert = dagger.make_expert(env)
        rows = np.flatnonzero(data["episode"] == k)
        assert len(rows) > 1
        again = np.stack([expert.predict(o)[0] for o in data["obs"][rows]])
        np.testing.assert_array_equal(again, data["labels"][rows])
        # the first observation is the env's reset with the recorded seed
        obs, _ = env.reset(seed=int(data["episode_env_seed"][k]))
        np.testing.assert_array_equal(obs, data["obs"][rows[0]])
    assert data["expert_acted"][data["iteration"] == 0].all()
    assert list(data["episode_beta"]) == [1.0, 0.5]


class _Recorder(gym.Wrapper):
    """Keeps the actions the env executed."""

    def __init__(self, env):
        super().__init__(env)
        self.actions = []

    def step(self, action):
        self.actions.append(np.array(action, dtype=float))
        return self.env.step(action)


class _ConstExpert:
    def __init__(self):
        self.seen = []

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        self.seen.append(np.array(obs))
        return np.array([0.3, 0.3]), None


@pytest.mark.parametrize("beta", [0.0, 0.5, 1.0])
def test_the_mixture_executes_the_actor_its_draws_pick(beta):
    kwargs = {**dagger.training_env_kwargs(0.05)}
    env = _Recorder(gym.make(tether_gym.ENV_ID, **kwargs))
    expert = _ConstExpert()
    episode = dagger.rollout(env, 7, expert, lambda o: np.array([-0.2, -0.2]), beta,
                             np.random.default_rng(3))
    steps = len(episode.obs)
    picks = np.random.default_rng(3).random(steps) < beta
    np.testing.assert_array_equal(episode.expert_acted, picks)
    executed = np.stack(env.actions)
    np.testing.assert_array_equal(executed[:, 0], np.where(picks, 0.3, -0.2))
    # the expert labels every observation, in order, whoever acts
    assert len(expert.seen) == steps
    np.testing.assert_array_equal(np.stack(expert.seen), episode.obs)
    np.testing.assert_array_equal(episode.labels, np.full((steps, 2), 0.3))
    if beta == 0.5:
        assert 0 < picks.sum() < steps


def test_the_saved_agent_is_the_network_on_normalised_observations(run):
    out, _, data = run
    agent = TrainedAgent.load(out)
    norm = agent.norm
    obs = data["obs"].astype(np.float64)
    np.testing.assert_allclose(norm.mean, obs.mean(axis=0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(norm.var, obs.var(axis=0), rtol=1e-12, atol=1e-18)
    assert agent.env_kwargs["action_mode"] == "rate"
    meta = json.loads((out / "agent.json").read_text())
    assert meta["training"]["method"] == "dagger" and meta["training"]["expert"] == "mpc"
    x = (data["obs"] - norm.mean) / np.sqrt(norm.var + norm.epsilon)
    x = np.clip(x, -norm.clip_obs, norm.clip_obs).astype(np.float32)
    with torch.no_grad():
        net = dagger.deterministic_action(agent.model, torch.as_tensor(x)).numpy()
    np.testing.assert_allclose(agent.predict(data["obs"])[0], np.clip(net, -1, 1), atol=1e-5)
    # the last checkpoint is the final agent
    last = sorted((out / "checkpoints").iterdir(), key=lambda p: int(p.name.split("_")[1]))[-1]
    final, checkpoint = (load_file(str(p / "policy.safetensors")) for p in (out, last))
    assert all(torch.equal(final[k], checkpoint[k]) for k in final)


def test_evaluate_scores_the_folder(run, tmp_path):
    out, _, _ = run
    with contextlib.redirect_stdout(io.StringIO()):
        code = evaluate_main([str(out), "--seeds", "1", "--no-plots", "--suite", "paper",
                              "--env-kwargs", "orbits_per_episode=0.2", "--out", str(tmp_path)])
    assert code == 0
    results = json.loads((tmp_path / "results.json").read_text())
    row = results["policies"][str(out)]
    assert row["kind"] == "rl" and row["n_episodes"] == 1
    assert row["env_kwargs"]["action_mode"] == "rate"


def test_same_seed_same_run(run, tmp_path):
    out, _, data = run
    code, _ = _train(tmp_path / "again")
    assert code == 0
    again = dict(np.load(tmp_path / "again" / dagger.DATA_FILE))
    assert sorted(again) == sorted(data)
    for key in data:
        np.testing.assert_array_equal(again[key], data[key])
    # the weights, tensor by tensor (the file's bytes are not: safetensors writes its
    # metadata entries in a varying order)
    first, second = (load_file(str(p / "policy.safetensors")) for p in (out, tmp_path / "again"))
    assert sorted(first) == sorted(second)
    for key in first:
        assert torch.equal(first[key], second[key]), key


def test_the_episode_mixture_gives_each_episode_one_actor(tmp_path):
    code, text = _train(tmp_path / "episodes", ["--mixture", "episode", "--iterations", "3",
                                                "--episodes", "3"])
    assert code == 0, text
    data = np.load(tmp_path / "episodes" / dagger.DATA_FILE)
    betas = data["episode_beta"]
    assert set(betas.tolist()) <= {0.0, 1.0} and betas[:3].tolist() == [1.0] * 3
    for k, beta in enumerate(betas):  # the recorded actor flew every step of its episode
        assert (data["expert_acted"][data["episode"] == k] == bool(beta)).all()
    # the episodes' actors are mpc's with the draws of their mixture seeds
    later = [np.random.default_rng(int(s)).random() < 0.5 ** (k // 3)
             for k, s in enumerate(data["episode_mixture_seed"])]
    assert betas.tolist() == [float(x) for x in later]


@pytest.mark.parametrize("argv, named", [
    (["--iterations", "0"], "--iterations 0 fits on shared data alone: give --data NPZ"),
    (["--iterations", "101"], "--iterations=101: allowed an integer in [0, 100]"),
    (["--expert-noise", "-0.1"], "--expert-noise=-0.1: allowed a number in [0, 2]"),
    (["--gate", "inf"], "--gate=inf: allowed a number in [0, 2]"),
    (["--symlog-scale", "0"], "--symlog-scale=0.0: allowed a number in [1e-09, 10]"),
    (["--data", "no_such.npz"],
     "--data no_such.npz cannot be read (No such file or directory)"),
    (["--episodes", "-1"], "--episodes=-1"),
    (["--epochs", "0"], "--epochs=0"),
    (["--seed", "-3"], "--seed=-3"),
    (["--orbits", "0"], "--orbits=0.0: allowed a number in [0.01, 100]"),
    (["--orbits", "nan"], "--orbits=nan"),
    (["--beta-decay", "1.5"], "--beta-decay=1.5: allowed a number in [0, 1]"),
    (["--learning-rate", "0"], "--learning-rate=0.0"),
    (["--mixture", "both"], "--mixture: invalid choice: 'both'"),
    (["--net-arch", "0"], "--net-arch=(0,): allowed a tuple of 1 to 8 layer widths"),
    (["--iterations", "x"], "--iterations: invalid int value: 'x'"),
])
def test_bad_arguments_are_refused_before_any_work(argv, named, tmp_path, capsys):
    out = tmp_path / "never"
    try:
        code = train_main(["distill", *argv, "--out", str(out)])
    except SystemExit as exc:  # argparse's own type errors
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("train.py distill: error:")
    assert named in err
    assert not out.exists()


def test_out_that_is_a_file_or_cannot_be_made_is_refused(tmp_path, capsys):
    target = tmp_path / "file"
    target.write_text("x")
    assert train_main(["distill", "--out", str(target)]) == 2
    assert f"--out {str(target)!r}: is a file" in capsys.readouterr().err
    assert _train(target / "sub")[0] == 2
    err = capsys.readouterr().err
    assert f"--out {str(target / 'sub')!r}: cannot write there" in err
    assert len(err.strip().splitlines()) == 1


def test_an_earlier_run_in_out_is_refused_and_left_as_it_was(run, tmp_path, capsys):
    """No resume: a second run there would leave its checkpoints beside the first's."""
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(run[0], out)
    files = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert _train(out)[0] == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert err.startswith(f"train.py distill: error: --out {str(out)!r}: already holds an "
                          "earlier training run (checkpoints/agent_")
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == files


def test_expert_noise_perturbs_the_executed_action_not_the_label():
    """DART: the env executes clip(label + N(0, sigma)), the data keep the clean label."""
    env = _Recorder(gym.make(tether_gym.ENV_ID, **dagger.training_env_kwargs(0.05)))
    episode = dagger.rollout(env, 7, _ConstExpert(), None, 1.0, np.random.default_rng(3),
                             expert_noise=0.5)
    draws = np.random.default_rng(3)
    expected = [np.clip(0.3 + draws.normal(0.0, 0.5, 2), -1, 1) for _ in episode.obs]
    np.testing.assert_array_equal(np.stack(env.actions), np.stack(expected))
    assert (np.stack(expected) == 1.0).any()  # the clip is exercised
    np.testing.assert_array_equal(episode.labels, np.full((len(episode.obs), 2), 0.3))
    assert episode.expert_acted.all()


class _FilteredConstExpert(_ConstExpert):
    """An expert with a safety filter: ``project`` halves the command it is given."""

    def project(self, obs, action):
        return 0.5 * np.asarray(action)


def test_expert_noise_goes_through_the_experts_filter():
    env = _Recorder(gym.make(tether_gym.ENV_ID, **dagger.training_env_kwargs(0.05)))
    episode = dagger.rollout(env, 7, _FilteredConstExpert(), None, 1.0,
                             np.random.default_rng(3), expert_noise=0.5)
    draws = np.random.default_rng(3)
    expected = [0.5 * np.clip(0.3 + draws.normal(0.0, 0.5, 2), -1, 1) for _ in episode.obs]
    np.testing.assert_array_equal(np.stack(env.actions), np.stack(expected))


@pytest.mark.parametrize("gate, taken", [(0.4, True), (0.6, False)])
def test_the_gate_hands_the_rest_of_the_episode_to_the_expert(gate, taken):
    """The student's -0.2 departs from the label 0.3 by 0.5: over a gate of 0.4 the
    expert flies every later step; under a gate of 0.6 the student keeps flying."""
    env = _Recorder(gym.make(tether_gym.ENV_ID, **dagger.training_env_kwargs(0.05)))
    episode = dagger.rollout(env, 7, _ConstExpert(), lambda o: np.array([-0.2, -0.2]), 0.0,
                             np.random.default_rng(3), gate=gate)
    steps = len(episode.obs)
    expert_steps = np.arange(steps) > 0 if taken else np.zeros(steps, bool)
    np.testing.assert_array_equal(episode.expert_acted, expert_steps)
    np.testing.assert_array_equal(np.stack(env.actions)[:, 0],
                                  np.where(expert_steps, 0.3, -0.2))


def test_shared_data_alone_is_behaviour_cloning_with_features(run, tmp_path):
    """--data NPZ --iterations 0: one fit on the shared pairs, no label spent; with
    --symlog-scale the saved agent is the network on the normalised observation and its
    symlog error features."""
    out, _, data = run
    code, text = _train(tmp_path / "bc", ["--data", str(out / dagger.DATA_FILE),
                                          "--iterations", "0", "--symlog-scale", "1e-4"])
    assert code == 0, text
    again = dict(np.load(tmp_path / "bc" / dagger.DATA_FILE))
    for key in data:
        np.testing.assert_array_equal(again[key], data[key])
    log = json.loads((tmp_path / "bc" / ITERATION_LOG_FILE).read_text())
    assert [r["labels"] for r in log] == [len(data["obs"])] and log[0]["labels_per_s"] is None
    info = json.loads((tmp_path / "bc" / "train_info.json").read_text())
    assert info["labels_per_s"] is None and "no labelling" in text
    agent = TrainedAgent.load(tmp_path / "bc")
    assert agent.features is not None and agent.features.scale == 1e-4
    n = 2
    sl = tether_gym.envs.layout.OBSERVATION.slices(n)
    e = data["obs"][:, sl["error"]].astype(np.float64)
    de = data["obs"][:, sl["derror"]].astype(np.float64)
    inputs = np.concatenate([data["obs"], np.sign(e) * np.log1p(np.abs(e) / 1e-4),
                             np.sign(de) * np.log1p(np.abs(de) / 1e-4)], axis=1)
    norm = agent.norm
    np.testing.assert_allclose(norm.mean, inputs.mean(axis=0), rtol=1e-6, atol=1e-9)
    x = np.clip((inputs - norm.mean) / np.sqrt(norm.var + norm.epsilon), -10, 10)
    with torch.no_grad():
        net = dagger.deterministic_action(agent.model, torch.as_tensor(x.astype(np.float32)))
    np.testing.assert_allclose(agent.predict(data["obs"])[0], np.clip(net.numpy(), -1, 1),
                               atol=1e-5)


def test_shared_data_then_labelled_iterations(run, tmp_path, monkeypatch):
    """After the fit on the shared data (iteration 0) come the labelled iterations; with
    --drop-failed a terminated episode's pairs are left out and counted."""
    out, _, data = run
    real = dagger.rollout

    def first_fails(*args, **kwargs):
        episode = real(*args, **kwargs)
        if not calls:
            episode.survived = False
        calls.append(len(episode.obs))
        return episode

    calls: list[int] = []
    monkeypatch.setattr(dagger, "rollout", first_fails)
    code, text = _train(tmp_path / "more", ["--data", str(out / dagger.DATA_FILE),
                                            "--iterations", "1", "--episodes", "2",
                                            "--drop-failed", "--check-episodes", "0"])
    assert code == 0, text
    more = dict(np.load(tmp_path / "more" / dagger.DATA_FILE))
    shared = len(data["obs"])
    np.testing.assert_array_equal(more["obs"][:shared], data["obs"])
    assert len(more["obs"]) == shared + calls[1]
    assert set(more["iteration"][shared:].tolist()) == {1}
    assert more["episode"][shared:].min() == data["episode"].max() + 1
    log = json.loads((tmp_path / "more" / ITERATION_LOG_FILE).read_text())
    assert [r["iteration"] for r in log] == [0, 1]
    assert log[1]["dropped_labels"] == calls[0] and log[1]["beta"] == 0.5


def test_init_policy_flies_from_iteration_1_with_its_statistics(run, tmp_path):
    """--init-policy AGENT: iteration 0 only checks the agent (no labels, no refit, its
    actor and statistics as the checkpoint); iteration 1's episode is flown by that agent
    alone (beta 0: replayed here, bitwise the same observations) and labelled by mpc; the
    refit keeps the agent's observation statistics."""
    out, _, _ = run
    start = TrainedAgent.load(out)
    code, text = _train(tmp_path / "ft", ["--init-policy", str(out), "--iterations", "1",
                                          "--beta-decay", "0"])
    assert code == 0, text
    log = json.loads((tmp_path / "ft" / ITERATION_LOG_FILE).read_text())
    assert [(r["iteration"], r["labels"], r["loss"]) for r in log][0] == (0, 0, None)
    assert log[1]["labels"] > 0 and log[1]["loss"] > 0
    assert "iteration 0 (the starting policy, before any label): 0 episodes, 0 labels" in text
    assert "loss n/a (no refit)" in text and "iteration 1 (beta 0, expert acted 0.00)" in text
    first = tmp_path / "ft" / "checkpoints" / "agent_0_steps"
    theirs, mine = load_file(out / "policy.safetensors"), load_file(first / "policy.safetensors")
    for key in theirs:
        if key.startswith(("mlp_extractor.policy_net", "action_net")):
            torch.testing.assert_close(mine[key], theirs[key], rtol=0, atol=0)
    for folder in (first, tmp_path / "ft"):
        norm = TrainedAgent.load(folder).norm
        np.testing.assert_array_equal(norm.mean, start.norm.mean)
        np.testing.assert_array_equal(norm.var, start.norm.var)
    data = dict(np.load(tmp_path / "ft" / dagger.DATA_FILE))
    assert not data["expert_acted"].any()
    kwargs = {k: v for k, v in dagger.training_env_kwargs(float(ORBITS)).items()
              if k not in ("eccentricity_range", "mass_range")}
    env = gym.make(tether_gym.ENV_ID, **kwargs, eccentricity=float(data["episode_eccentricity"][0]),
                   masses=tuple(float(m) for m in data["episode_masses"][0]))
    episode = dagger.rollout(env, int(data["episode_env_seed"][0]),
                             student=lambda o: start.predict(o, deterministic=True)[0])
    np.testing.assert_array_equal(episode.obs, data["obs"])


@pytest.mark.parametrize("extra, named", [
    (["--symlog-scale", "1e-4"], "input features"),
    (["--net-arch", "16", "16"], "layers"),
    (["--init-policy", "no/such/agent"], "does not exist"),
])
def test_init_policy_that_does_not_fit_is_refused_before_the_folder(run, tmp_path, capsys,
                                                                     extra, named):
    out, _, _ = run
    code, _ = _train(tmp_path / "bad", ["--init-policy", str(out), *extra])
    assert code == 2
    err = capsys.readouterr().err
    assert "init_policy" in err and named in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "bad").exists()
