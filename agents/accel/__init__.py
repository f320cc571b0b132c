"""The accelerator path: the libration env batched on a torch device, and PPO trained there.

* :mod:`.chain`: the step of ``TetherLibration-v1`` (physics, reward, termination,
  observation) on torch tensors, a port of the numba step tested equal to it;
* :mod:`.vec_env`: :class:`~.vec_env.TorchTetherVecEnv`, thousands of envs on one device;
* :mod:`.ppo`: PPO with several seeds trained at once on the device, writing standard
  agent folders that ``evaluate.py`` scores on the numba env;
* :mod:`.graphs`: PPO's minibatch step captured as a CUDA graph and replayed
  (``--cuda-graphs``);
* :mod:`.cli`: ``python train.py gpu ...``.

Needs torch (``pip install -e ".[gpu]"`` on a CUDA machine; the CPU build works too).
"""
