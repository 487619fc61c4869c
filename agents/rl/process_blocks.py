"""A Stable-Baselines3 ``VecEnv`` whose sub-environments run in worker processes, each worker
stepping a contiguous block of them in lockstep.

One process steps the batched environments of :func:`agents.rl.vector.stable_baselines_vec_env`
on one core; PPO's rollouts spend most of their time there (docs/performance.md). SB3's
``SubprocVecEnv`` puts one environment in each process, which gives up the lockstep
batching of the trackers' learning. :func:`process_blocks_vec_env` splits the ``n_envs``
sub-environments into ``workers`` contiguous blocks, and worker k holds block k as its own
batched ``VecEnv`` (``stable_baselines_vec_env``), pinned to a core of its own
(:func:`worker_cores`). Each sub-environment's numbers do not depend on its block (each
tracker's numbers are bit for bit those of its episode alone,
:meth:`~dgpt_gym.tracker.TrackerBase.update_batch`), so the whole equals the one-process
``VecEnv`` step for step: observations, rewards, dones and infos; a model trained on it is
the one trained in one process.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from functools import partial

import numpy as np
from threadpoolctl import threadpool_limits

from agents.rl.vector import stable_baselines_vec_env
from dgpt_gym.validation import check_integer

__all__ = ["process_blocks_vec_env", "block_bounds", "worker_cores"]


def block_bounds(n_envs: int, workers: int) -> list[tuple[int, int]]:
    """The contiguous blocks ``[(start, stop), ...]`` of ``n_envs`` sub-environments over
    ``workers`` processes, as even as they can be (the first ``n_envs % workers`` blocks
    one larger), so a lockstep step waits for a block at most one larger than another."""
    check_integer("n_envs", n_envs, low=1)
    if check_integer("workers", workers, low=1) > n_envs:
        raise ValueError(f"workers must be at most n_envs = {n_envs}; got {workers}")
    sizes = np.full(workers, n_envs // workers)
    sizes[: n_envs % workers] += 1
    stops = np.cumsum(sizes)
    return [(int(stop - size), int(stop)) for size, stop in zip(sizes, stops)]


def worker_cores(workers: int) -> list[int | None]:
    """The core each of ``workers`` processes is pinned to: one core of this process's
    affinity mask each, in order, where the platform can pin (Linux) and there are at least
    as many cores as workers; else None (the scheduler places them). Unpinned, the scheduler
    moved two workers between the two cores of this project's machine, whose L2 caches are
    their own, and a worker's step took about 1.3x as long inside PPO
    (docs/performance.md)."""
    if not hasattr(os, "sched_setaffinity"):
        return [None] * workers
    cores = sorted(os.sched_getaffinity(0))
    return cores[:workers] if workers <= len(cores) else [None] * workers


def _serve(remote, parent_remote, make_block, core: int | None) -> None:
    """A worker's loop: pinned to ``core`` (unless None), build its block's ``VecEnv`` and
    run the parent's commands ``(command, args)`` on it until "close"; each reply is
    ``(True, value)``, or ``(False, exception)`` for the parent to raise."""
    parent_remote.close()
    if core is not None:
        os.sched_setaffinity(0, {core})
    threadpool_limits(limits=1)  # the trackers' matrices are tiny; the workers share the cores
    venv = None
    while True:
        try:
            command, args = remote.recv()
        except (EOFError, KeyboardInterrupt):
            break
        if command == "close":
            if venv is not None:
                venv.close()
            remote.close()
            break
        try:
            if venv is None:
                venv = make_block()
            if command == "step":
                value = (*venv.step(args), venv.reset_infos)
            elif command == "reset":
                seed, options = args
                if seed is not None:
                    venv.seed(seed)
                venv.set_options(options)
                value = (venv.reset(), venv.reset_infos)
            elif command == "spaces":
                value = (venv.observation_space, venv.action_space)
            else:  # get_attr, set_attr, env_method, env_is_wrapped, with local indices
                value = getattr(venv, command)(*args[0], **args[1])
        except Exception as error:  # noqa: BLE001 - raised again in the parent
            remote.send((False, error))
        else:
            remote.send((True, value))


def _receive(remotes) -> list:
    """The replies of the workers at ``remotes``, every one read (so none is left in a pipe)
    before the first worker's exception, if any, is raised here."""
    replies = [remote.recv() for remote in remotes]
    for ok, value in replies:
        if not ok:
            raise value
    return [value for _, value in replies]


def process_blocks_vec_env(
    env_id: str,
    n_envs: int,
    seed: int,
    env_kwargs: dict | None = None,
    workers: int = 2,
    start_method: str | None = None,
):
    """A Stable-Baselines3 ``VecEnv`` of ``n_envs`` sub-environments ``env_id`` (keyword
    arguments ``env_kwargs``) in ``workers`` processes, each stepping its contiguous block
    (:func:`block_bounds`) in lockstep (module docstring); sub-environment i is seeded
    ``seed + i`` at the first reset, as in
    :func:`~agents.rl.vector.stable_baselines_vec_env`. Worker processes start by
    ``start_method`` (multiprocessing's; by default SB3's ``SubprocVecEnv``'s, "forkserver"
    where the platform has it, else "spawn"; as with ``SubprocVecEnv``, a script that makes
    one needs the ``if __name__ == "__main__":`` guard); ``close`` ends them. An exception
    in a worker is raised in this process. Needs the 'rl' extra."""
    from stable_baselines3.common.vec_env import VecEnv

    blocks = block_bounds(n_envs, workers)
    if start_method is None:
        start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
    context = mp.get_context(start_method)

    class ProcessBlocksVecEnv(VecEnv):
        def __init__(self) -> None:
            self.blocks = blocks
            self.remotes, self.processes = [], []
            self.waiting = self.closed = False
            for (start, stop), core in zip(self.blocks, worker_cores(len(blocks))):
                remote, work_remote = context.Pipe()
                make_block = partial(
                    stable_baselines_vec_env, env_id, stop - start, seed + start, env_kwargs
                )
                process = context.Process(
                    target=_serve,
                    args=(work_remote, remote, make_block, core),
                    daemon=True,
                )
                process.start()
                work_remote.close()
                self.remotes.append(remote)
                self.processes.append(process)
            for remote in self.remotes:
                remote.send(("spaces", None))
            try:  # a bad env_id or env_kwargs fails here, in every worker
                observation_space, action_space = _receive(self.remotes)[0]
            except Exception:
                self.closed = True
                for remote, process in zip(self.remotes, self.processes):
                    remote.send(("close", None))
                    process.join()
                raise
            super().__init__(n_envs, observation_space, action_space)
            self.seed(seed)

        def step_async(self, actions: np.ndarray) -> None:
            for remote, (start, stop) in zip(self.remotes, self.blocks):
                remote.send(("step", actions[start:stop]))
            self.waiting = True

        def step_wait(self):
            self.waiting = False
            results = _receive(self.remotes)
            observations, rewards, dones, infos, reset_infos = zip(*results)
            self.reset_infos = [info for block in reset_infos for info in block]
            return (
                np.concatenate(observations),
                np.concatenate(rewards),
                np.concatenate(dones),
                [info for block in infos for info in block],
            )

        def reset(self):
            for remote, (start, stop) in zip(self.remotes, self.blocks):
                remote.send(("reset", (self._seeds[start], self._options[start:stop])))
            results = _receive(self.remotes)
            observations, reset_infos = zip(*results)
            self.reset_infos = [info for block in reset_infos for info in block]
            self._reset_seeds()
            self._reset_options()
            return np.concatenate(observations)

        def close(self) -> None:
            if self.closed:
                return
            if self.waiting:
                for remote in self.remotes:
                    remote.recv()
            for remote in self.remotes:
                remote.send(("close", None))
            for process in self.processes:
                process.join()
            for remote in self.remotes:
                remote.close()
            self.closed = True

        def _call(self, command: str, indices, *args, **kwargs) -> list:
            """``command`` on the sub-environments ``indices`` (all by default), each worker
            asked once for its own; the values in the order of ``indices``."""
            indices = list(self._get_indices(indices))
            asked, order = [], []
            for remote, (start, stop) in zip(self.remotes, self.blocks):
                own = [index for index in indices if start <= index < stop]
                if own:
                    local = [index - start for index in own]
                    remote.send((command, (args, {**kwargs, "indices": local})))
                    asked.append(remote)
                    order.extend(own)
            replies = _receive(asked)
            if all(reply is None for reply in replies):  # set_attr
                return []
            values = dict(zip(order, (value for reply in replies for value in reply)))
            return [values[index] for index in indices]

        def get_attr(self, attr_name: str, indices=None) -> list:
            return self._call("get_attr", indices, attr_name)

        def set_attr(self, attr_name: str, value, indices=None) -> None:
            self._call("set_attr", indices, attr_name, value)

        def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list:
            return self._call("env_method", indices, method_name, *method_args, **method_kwargs)

        def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
            return self._call("env_is_wrapped", indices, wrapper_class)

    return ProcessBlocksVecEnv()
