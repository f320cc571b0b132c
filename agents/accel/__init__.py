"""The accelerator path: the libration env batched on a torch device, and PPO trained there.

* :mod:`.chain`: the step of ``TetherLibration-v1`` (physics, reward, termination,
  observation) on torch tensors, a port of the numba step tested equal to it;
* :mod:`.vec_env`: :class:`~.vec_env.TorchTetherVecEnv`, thousands of envs on one device;
* :mod:`.ppo`, :mod:`.rollout`, :mod:`.trainer`: PPO with several seeds trained at once
  on the device (the policy, the rollout, the updates), writing standard agent folders
  that ``evaluate.py`` scores on the numba env;
* :mod:`.graphs`: the rollout's pieces and the minibatch step captured as CUDA graphs
  and replayed (``--cuda-graphs``);
* :mod:`.cli`: ``python train.py gpu ...``.

Needs torch (``pip install -e ".[gpu]"`` on a CUDA machine; the CPU build works too).
"""
