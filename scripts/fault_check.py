"""Do the tests fail when the mathematics is wrong? Apply each deliberate fault of
:data:`FAULTS` to a copy of the code and run the tests on it: a fault is *caught* when at
least one test fails, *survived* when all pass. The faults are issue 12's goal 7 (every
expert returns its prior, the trend's variance set to zero, the UCB half-width x10 and x0.1,
the anytime UCB's step offset by 100, the hybrid's Poisson update skipped, the hybrid's
bound x0.1) and a few of the same kind: the reported variance scaled, RBCM's and GPoE's
entropy weights (eq. (11)) halved.

The working tree is never touched: each fault is applied in a fresh temporary copy of
``agents``, ``baselines``, ``dgpt_gym``, ``scripts``, ``tests`` and ``pyproject.toml``,
and pytest runs there; the table counts the tests that fail and names a few. Before the
faults the unchanged copy must pass the same tests, or the check stops. A fault whose text
is no longer in the code is an error that names it, so the list cannot silently go stale.
Writes a Markdown table (``--out``, rewritten after every fault, so an interrupted run
keeps the rows it finished). About 25 min on one core.

    python scripts/fault_check.py --out docs/fault_check.md
    python scripts/fault_check.py --faults hybrid-update-skipped hybrid-bound-x0.1
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1]

COPIED = ("agents", "baselines", "dgpt_gym", "scripts", "tests", "pyproject.toml")
"""What the copy holds: the packages, the scripts some tests run, the tests and the pytest
settings (which turn RuntimeWarnings into errors)."""

TESTS = ("tests/test_agents", "--ignore=tests/test_agents/rl")
"""The tests run on every fault: those of the trackers' mathematics (about 100 s when all
pass; the RL environments' tests wrap these trackers and are left out for time)."""


class Fault(NamedTuple):
    """A deliberate error: ``old`` replaced by ``new`` in ``path`` (relative to the
    repository), where ``old`` must occur exactly once."""

    name: str
    description: str
    path: str
    old: str
    new: str


FAULTS = (
    Fault(
        "experts-return-prior",
        "every expert of the state-space trackers returns its prior: what it updates with "
        "carries no information (variance 1e12)",
        "agents/state_space_dgpt.py",
        "        if self.aggregation in POOLED_METHODS:  # the sums serve",
        "        update_var = 1e12 + update_var\n"
        "        if self.aggregation in POOLED_METHODS:  # the sums serve",
    ),
    Fault(
        "experts-update-with-summaries",
        "the state-space trackers' experts update with their summaries as measurements "
        "instead of with their sensors' mixture posteriors (the PDA moments)",
        "agents/state_space_dgpt.py",
        'if self.expert_update == "mixture":',
        "if False:",
    ),
    Fault(
        "no-gating-mixture-update",
        "without gating, the state-space trackers' experts update with the mixture over their "
        "sensors' equally weighted points instead of with the unweighted mean and its spread",
        "agents/state_space_dgpt.py",
        'if self.expert_update == "mixture":',
        'if self.expert_update == "mixture" or not self.gating:',
    ),
    Fault(
        "trend-experts-return-prior",
        "every expert of the `-trend` and `-paper` trackers returns its prior mean "
        "(the residual GP's mean 0)",
        "agents/dgpt.py",
        "mean_now, var_now = gp.predict(log_params, self.training, None, None, x_now, fact)",
        "mean_now, var_now = gp.predict(log_params, self.training, None, None, x_now, fact)\n"
        "        mean_now = 0.0 * mean_now",
    ),
    Fault(
        "trend-variance-zero",
        "the trend's (the basis's) estimation variance left out of the `-trend` trackers' variance",
        "agents/dgpt.py",
        "trend_var = data.prior_mean_variance(relative_time, residual_var)",
        "trend_var = 0.0 * data.prior_mean_variance(relative_time, residual_var)",
    ),
    Fault(
        "ucb-x10",
        "the state-space trackers' UCB half-width multiplied by 10",
        "agents/state_space_dgpt.py",
        "return Estimate(mean[:, 0].copy(), var.copy(), ucb, prior_next)",
        "return Estimate(mean[:, 0].copy(), var.copy(), 10.0 * ucb, prior_next)",
    ),
    Fault(
        "ucb-x0.1",
        "the state-space trackers' UCB half-width multiplied by 0.1",
        "agents/state_space_dgpt.py",
        "return Estimate(mean[:, 0].copy(), var.copy(), ucb, prior_next)",
        "return Estimate(mean[:, 0].copy(), var.copy(), 0.1 * ucb, prior_next)",
    ),
    Fault(
        "trend-ucb-x10",
        "the `-trend` trackers' UCB half-width (Theorem 2) multiplied by 10",
        "agents/aggregation.py",
        "        + np.abs(prior_coefficient) * np.sqrt(gamma) * prior_std\n    )",
        "        + np.abs(prior_coefficient) * np.sqrt(gamma) * prior_std\n    ) * 10.0",
    ),
    Fault(
        "trend-ucb-x0.1",
        "the `-trend` trackers' UCB half-width (Theorem 2) multiplied by 0.1",
        "agents/aggregation.py",
        "        + np.abs(prior_coefficient) * np.sqrt(gamma) * prior_std\n    )",
        "        + np.abs(prior_coefficient) * np.sqrt(gamma) * prior_std\n    ) * 0.1",
    ),
    Fault(
        "anytime-step-plus-100",
        "the anytime UCB's step t (Lemma 2's gamma_t) offset by 100",
        "agents/dgpt.py",
        "step=(steps + 1)[:, None] if first.anytime_ucb else None,",
        "step=(steps + 101)[:, None] if first.anytime_ucb else None,",
    ),
    Fault(
        "hybrid-update-skipped",
        "the hybrid's Poisson update skipped: it returns the DGPT's estimate",
        "agents/hybrid.py",
        "        if prior is None:\n            return learned",
        "        if True:\n            return learned",
    ),
    Fault(
        "hybrid-bound-x0.1",
        "the hybrid's bound multiplied by 0.1",
        "agents/hybrid.py",
        "return Estimate(mean, var, bound, prior_next)",
        "return Estimate(mean, var, 0.1 * bound, prior_next)",
    ),
    Fault(
        "entropy-weights-halved",
        "the state-space RBCM's and GPoE's expert weights beta_i (eq. (11)) halved",
        "agents/state_space.py",
        "return 0.5 * np.log1p(np.asarray(prior_var)[..., None] / noise_var)",
        "return 0.25 * np.log1p(np.asarray(prior_var)[..., None] / noise_var)",
    ),
    Fault(
        "variance-x4",
        "the state-space trackers report 4 times their variance",
        "agents/state_space_dgpt.py",
        "var = cov[:, 0, 0] if var is None else var",
        "var = 4.0 * (cov[:, 0, 0] if var is None else var)",
    ),
    Fault(
        "variance-x0.25",
        "the state-space trackers report a quarter of their variance",
        "agents/state_space_dgpt.py",
        "var = cov[:, 0, 0] if var is None else var",
        "var = 0.25 * (cov[:, 0, 0] if var is None else var)",
    ),
)

_STATUS = {0: "**survived**", 1: "caught"}
"""pytest's exit code -> the outcome; any other code (an error in collection, a usage
error) is reported as an error: the fault broke the code, no test judged it."""


def copy_source(destination: Path, root: Path = ROOT) -> Path:
    """Copy :data:`COPIED` from ``root`` into ``destination`` (without caches) and return
    ``destination``."""
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", ".pytest_cache")
    for name in COPIED:
        source = root / name
        if source.is_dir():
            shutil.copytree(source, destination / name, ignore=ignore)
        else:
            shutil.copy2(source, destination / name)
    return destination


def faulty_text(text: str, fault: Fault) -> str:
    """``text`` with ``fault.old`` replaced by ``fault.new``; a ValueError naming the fault
    when ``old`` does not occur exactly once."""
    count = text.count(fault.old)
    if count != 1:
        raise ValueError(
            f"fault {fault.name!r}: its text occurs {count} times in {fault.path} (it must "
            f"occur once; update FAULTS to the code): {fault.old!r}"
        )
    return text.replace(fault.old, fault.new)


def apply_fault(root: Path, fault: Fault) -> None:
    """Apply ``fault`` to the copy at ``root`` (:func:`faulty_text`)."""
    path = root / fault.path
    path.write_text(faulty_text(path.read_text(), fault))


def run_tests(root: Path, tests=TESTS) -> tuple[int, list[str], float]:
    """Run pytest on ``tests`` in the copy at ``root``. Returns (pytest's exit code, the ids
    of the tests that failed or errored, seconds)."""
    environment = {**os.environ, "PYTHONPATH": str(root), "PYTHONDONTWRITEBYTECODE": "1"}
    check = subprocess.run(
        [sys.executable, "-c", "import agents; print(agents.__file__)"],
        cwd=root,
        env=environment,
        capture_output=True,
        text=True,
    )
    if not check.stdout.strip().startswith(str(root)):
        raise RuntimeError(f"the copy's packages are not the ones imported: {check.stdout}")
    start = time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-rfE", "-p", "no:cacheprovider", *tests],
        cwd=root,
        env=environment,
        capture_output=True,
        text=True,
    )
    failed = re.findall(r"^(?:FAILED|ERROR) (\S+)", result.stdout, flags=re.M)
    return result.returncode, failed, time.perf_counter() - start


def check_fault(fault: Fault | None, tests=TESTS, root: Path = ROOT):
    """(outcome, failing tests, seconds) of ``fault`` (None: the unchanged code) in a fresh
    copy of ``root``."""
    with tempfile.TemporaryDirectory(prefix="fault-check-") as folder:
        copy = copy_source(Path(folder), root)
        if fault is not None:
            apply_fault(copy, fault)
        code, failed, seconds = run_tests(copy, tests)
    return _STATUS.get(code, f"error (pytest exit code {code})"), failed, seconds


REPORT_HEADER = """# Deliberate faults and the tests that catch them

Generated by `python scripts/fault_check.py --out docs/fault_check.md`: each fault is applied
to a temporary copy of the code, and the tests of the trackers' mathematics
(`pytest tests/test_agents --ignore=tests/test_agents/rl`) run on it. "caught": at least one
test fails; "survived": every test passes. The unchanged copy passes the same tests first.
The faults and their exact text are `FAULTS` in the script.

"""

SHOWN_TESTS = 3
"""How many of a fault's failing tests the table names."""


def table(rows) -> str:
    """The Markdown table of the checked faults, ``rows`` of (fault, outcome, failing
    tests, seconds)."""
    lines = [
        "| fault | what it does | where | outcome | failing tests | among them | s |",
        "|---|---|---|---|---|---|---|",
    ]
    for fault, outcome, failed, seconds in rows:
        names = [f"`{test.removeprefix('tests/test_agents/')}`" for test in failed]
        shown = "<br>".join(names[:SHOWN_TESTS] + ["..."] * (len(names) > SHOWN_TESTS))
        lines.append(
            f"| `{fault.name}` | {fault.description} | `{fault.path}` | {outcome} "
            f"| {len(failed)} | {shown or '-'} | {seconds:.0f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    names = [fault.name for fault in FAULTS]
    parser.add_argument("--faults", nargs="+", choices=names, default=names, metavar="NAME")
    parser.add_argument("--out", type=Path, help="write the Markdown table here as it grows")
    args = parser.parse_args(argv)
    faults = [fault for fault in FAULTS if fault.name in args.faults]
    for fault in faults:  # a stale fault fails before any test runs
        faulty_text((ROOT / fault.path).read_text(), fault)
    outcome, failed, seconds = check_fault(None)
    if outcome != _STATUS[0]:
        print(f"the unchanged code does not pass ({outcome}, {failed[:3]}): fix it first")
        return 1
    print(f"the unchanged code passes the tests ({seconds:.0f} s)", flush=True)
    rows = []
    for fault in faults:
        outcome, failed, seconds = check_fault(fault)
        rows.append((fault, outcome, failed, seconds))
        print(f"{fault.name}: {outcome}, {len(failed)} failing ({seconds:.0f} s)", flush=True)
        if args.out:
            args.out.write_text(REPORT_HEADER + table(rows))
    print(table(rows))
    return int(any(outcome != _STATUS[1] for _, outcome, _, _ in rows))


if __name__ == "__main__":
    sys.exit(main())
