"""Can a policy that sees only the observation take the clairvoyant's gain? A one-step
improvement of the best fixed setting, learned from the observation.

The greedy clairvoyant policy (:mod:`agents.rl.clairvoyant`) beats the best fixed window or
gate threshold by knowing each step's error. This script asks how much of that an
observation can predict:

1. On fit seeds (1000 onwards) it runs the best fixed setting and, at every step, tries every
   fixed setting on copies of the environment, recording the observation and each
   setting's reward minus the best fixed setting's (its one-step advantage).
2. A regression tree (scikit-learn) learns the advantages from the observation; the policy
   takes the setting with the highest predicted advantage, and the best fixed setting where
   none is predicted above zero. That is one step of policy improvement over the best
   fixed setting, with the observation as its only input. The tree's minimum leaf size is
   chosen by the mean return on the selection seeds that follow the fit seeds.
3. On the evaluation seeds 0..N-1 it reports the learned policy's return paired with the
   best fixed setting's, seed by seed.

If the learned policy gains nothing, the clairvoyant's gain rests on what the observation
does not show, and no agent with this observation could be expected to take it.

    python scripts/clairvoyant_imitation.py --env DGPTrackWindow-v0
    python scripts/clairvoyant_imitation.py --env DGPTrackGating-v0

Each fit seed's records and each fixed setting's training episodes are cached in
``results/rl/clairvoyant_imitation`` (``--cache``) as they finish.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import gymnasium as gym  # noqa: E402
from sklearn.tree import DecisionTreeRegressor  # noqa: E402

import dgpt_gym  # noqa: E402, F401  (registers the environments)
from agents.rl.clairvoyant import GreedyClairvoyantPolicy  # noqa: E402
from agents.rl.cli import TUNING_ENV_IDS, TUNING_TASK_KWARGS, parse_kwargs  # noqa: E402
from agents.rl.evaluation import paired_interval  # noqa: E402
from agents.rl.runs import best_fixed_setting, cached_json, code_digest, run_policies  # noqa: E402

LEAF_SIZES = (50, 200, 800)
"""Minimum samples per leaf tried for the tree (about 150 steps per seed)."""


class AdvantagePolicy:
    """The fixed setting with the highest advantage the ``tree`` predicts from the
    observation over ``fallback`` (the best fixed setting), or ``fallback`` where none is
    predicted above zero."""

    def __init__(self, tree, actions: list, fallback: int) -> None:
        self.tree, self.actions, self.fallback = tree, actions, fallback

    def predict(self, observation):
        advantage = self.tree.predict(np.asarray(observation, dtype=float)[None])[0]
        best = int(np.argmax(advantage))
        return self.actions[best if advantage[best] > 0 else self.fallback]


TREE_POLICY = {"tree": AdvantagePolicy}
""":func:`agents.rl.runs.run_policies`' rule of kind ``"tree"``: an :class:`AdvantagePolicy`
from its keyword arguments."""


def best_fixed_records(task) -> dict[str, list]:
    """One episode of the best fixed setting on ``seed``; at every step the observation and
    every fixed setting's one-step reward minus the best fixed setting's."""
    env_id, env_kwargs, best, seed = task
    env = gym.make(env_id, **env_kwargs)
    trials = GreedyClairvoyantPolicy(env)
    observation, _ = env.reset(seed=seed)
    observations, advantages, done = [], [], False
    while not done:
        trials.predict(observation)
        observations.append(np.asarray(observation, dtype=float).tolist())
        advantages.append((trials.last_rewards - trials.last_rewards[best]).tolist())
        observation, _, terminated, truncated, _ = env.step(trials.actions[best])
        done = terminated or truncated
    return {"observations": observations, "advantages": advantages}


def cached_records(task_and_cache) -> dict[str, list]:
    """:func:`best_fixed_records` of a task, kept in the cache folder under a key of the
    packages' code, this script's own (which records them) and the task."""
    task, cache = task_and_cache
    script = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()
    key = json.dumps([code_digest(), script, *task], sort_keys=True, default=str)
    path = cache / f"records-{hashlib.sha256(key.encode()).hexdigest()[:20]}.json"
    return cached_json(path, lambda: best_fixed_records(task))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default=TUNING_ENV_IDS[0], choices=TUNING_ENV_IDS)
    parser.add_argument("--fit-seeds", type=int, default=30, help="seeds 1000..1000+N-1")
    parser.add_argument("--select-seeds", type=int, default=10, help="the seeds after them")
    parser.add_argument("--seeds", type=int, default=100, help="evaluation seeds 0..N-1")
    parser.add_argument(
        "--training-seeds",
        type=int,
        default=20,
        help="seeds 1000.. on which the best fixed setting is chosen, as "
        "scripts/tuning_baselines.py chooses it",
    )
    parser.add_argument("--env-kwargs", nargs="*", default=TUNING_TASK_KWARGS, metavar="KEY=VALUE")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", type=Path, default=ROOT / "docs", help="where the report goes")
    parser.add_argument(
        "--cache", type=Path, default=ROOT / "results" / "rl" / "clairvoyant_imitation"
    )
    args = parser.parse_args(argv)
    if min(args.fit_seeds, args.select_seeds, args.seeds, args.workers, args.training_seeds) < 1:
        parser.error(
            "--fit-seeds, --select-seeds, --seeds, --training-seeds and --workers must be >= 1"
        )
    try:
        env_kwargs = parse_kwargs(args.env_kwargs)
        env = gym.make(args.env, **env_kwargs)
    except (TypeError, ValueError) as error:
        parser.error(f"--env-kwargs: {error}")
    settings, _ = env.unwrapped.fixed_actions()
    names, actions = list(settings), list(settings.values())
    best_name, _ = best_fixed_setting(
        args.env,
        env_kwargs,
        range(1000, 1000 + args.training_seeds),
        args.workers,
        args.cache,
    )
    best = names.index(best_name)
    report = [f"best fixed setting on training seeds 1000-{999 + args.training_seeds}: {best_name}"]
    print(report[-1])

    args.cache.mkdir(parents=True, exist_ok=True)
    fit = range(1000, 1000 + args.fit_seeds)
    select = range(fit[-1] + 1, fit[-1] + 1 + args.select_seeds)
    evaluation = range(args.seeds)
    with ProcessPoolExecutor(args.workers) as pool:
        tasks = [((args.env, env_kwargs, best, seed), args.cache) for seed in fit]
        records = list(pool.map(cached_records, tasks))
    x = np.concatenate([np.array(r["observations"]) for r in records])
    y = np.concatenate([np.array(r["advantages"]) for r in records])
    report.append(
        f"{len(x)} steps on fit seeds {fit[0]}-{fit[-1]}; one-step advantage over "
        f"{best_name}, mean of the best per step {y.max(axis=1).mean():.4f}"
    )
    print(report[-1])

    def returns(leaves, seeds) -> np.ndarray:
        """(1 + len(leaves), len(seeds)) returns: the best fixed setting's (cached) and
        the learned policy's for each minimum leaf size (not cached: a fitted tree is not
        named by its arguments)."""
        trees = [
            (
                "tree",
                {
                    "tree": DecisionTreeRegressor(min_samples_leaf=leaf, random_state=0).fit(x, y),
                    "actions": actions,
                    "fallback": best,
                },
            )
            for leaf in leaves
        ]
        rows = run_policies(
            [("constant", actions[best])],
            args.env,
            env_kwargs,
            seeds,
            args.workers,
            cache=args.cache,
        )
        rows += run_policies(trees, args.env, env_kwargs, seeds, args.workers, TREE_POLICY)
        return np.array([[row["return"] for row in policy_rows] for policy_rows in rows])

    fixed_and_learned = returns(LEAF_SIZES, select)
    scores = {}
    for leaf, learned in zip(LEAF_SIZES, fixed_and_learned[1:]):
        scores[leaf] = float(np.mean(learned - fixed_and_learned[0]))
        report.append(
            f"selection seeds {select[0]}-{select[-1]}: min leaf {leaf}, "
            f"mean return - {best_name} {scores[leaf]:+.3f}"
        )
        print(report[-1])
    leaf = max(scores, key=scores.get)
    fixed, learned = returns([leaf], evaluation)
    difference, half = paired_interval(learned - fixed)
    report.append(
        f"evaluation seeds 0-{args.seeds - 1}, min leaf {leaf}: learned one-step "
        f"improvement {learned.mean():.2f}, {best_name} {fixed.mean():.2f}, "
        f"paired {difference:+.2f} +- {half:.2f} (95 % t interval over seeds)"
    )
    print(report[-1])
    command = "python scripts/clairvoyant_imitation.py --env " + args.env
    slug = args.env.removeprefix("DGPTrack").lower().replace("-", "_")
    path = args.out / f"rl_imitation_{slug}.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        f"# {args.env}: one-step improvement over the best fixed setting, learned from the "
        f"observation ({', '.join(args.env_kwargs)})\n\n"
        f"Generated by `{command}` (with --fit-seeds {args.fit_seeds} --select-seeds "
        f"{args.select_seeds} --seeds {args.seeds}); see the script's docstring.\n\n"
        + "".join(f"- {line}\n" for line in report)
    )
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
