"""Fuzzing every reader and command: how malformed inputs end, counted per input class.

Each input class (``FUZZ_CLASSES`` of every ``tests/helpers/fuzz_*.py``: a reader and the
command that uses it) draws malformed variants of a valid file with hypothesis (truncation,
byte corruption, wrong types, extreme and non-finite numbers, empty and header-only files,
huge fields, wrong encodings and separators, degenerate data), runs the command in-process
through the CLI's own guard (``tests/helpers/fuzz.py``) and counts how each run ended:

- ok: exit 0; clear: exit 1 or 2 with an ``error:``/``warning:`` line naming the file;
- unnamed: a message that does not name the file; silent: a non-zero exit without a message;
- late: an input that must be refused before anything is done (a robot file outside the
  campaign, an unknown tip frame) that a command ran with;
- wrong: silently wrong, a case whose input gives plausible but wrong results (a rig file of
  another rig, a camera that measured nothing) without the warning or error that says so;
- bug: the guard's "internal error" line (exit 3); traceback: an exception escaped;
- hang: longer than the time limit.

Run: .venv/bin/python benchmarks/bench_fuzz.py [--examples 300] [--slow-examples 40] [--seed 1]
[--only NAME] [--update]

``--slow-examples``: inputs of the classes whose every case runs a whole campaign or capture
(``FuzzClass.slow``). ``--update``: keep the other classes' rows of ``results/fuzz.md`` and
replace (or add) those run now.
"""

from __future__ import annotations

import argparse
import collections
import importlib
import re
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from _table import save  # noqa: E402
from helpers.fuzz import HANDLED, OUTCOMES, FuzzClass, run_case  # noqa: E402
from hypothesis import HealthCheck, Phase, given, settings  # noqa: E402
from hypothesis import seed as seed_  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


def fuzz_classes() -> list[FuzzClass]:
    """Every FuzzClass of every ``tests/helpers/fuzz_*.py``, in file order."""
    out: list[FuzzClass] = []
    for p in sorted((HERE.parent / "tests" / "helpers").glob("fuzz_*.py")):
        out += importlib.import_module(f"helpers.{p.stem}").FUZZ_CLASSES
    return out


def count(cls: FuzzClass, examples: int, seed: int) -> tuple[collections.Counter, float, list[str]]:
    """Run ``examples`` cases of ``cls``; the outcome counts, the slowest run and the findings."""
    counts: collections.Counter = collections.Counter()
    findings: list[str] = []
    slowest = [0.0]

    @settings(
        max_examples=examples,
        deadline=None,
        database=None,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(st.data())
    def run(data) -> None:
        case = data.draw(cls.cases)
        o = run_case(case)
        counts[o.kind] += 1
        slowest[0] = max(slowest[0], o.seconds)
        if o.kind not in HANDLED:
            last = o.detail or (o.stderr.strip().splitlines() or [""])[-1]
            last = re.sub(r"/tmp/stiffmap-fuzz-\w+", "{dir}", last)[:200]
            what = f"{case.note} -> " if case.note else ""
            finding = f"{cls.name}: {o.kind}: {what}{last}"
            if finding not in findings and len(findings) < 5:
                findings.append(finding)

    seed_(seed)(run)()
    return counts, slowest[0], findings


def _saved_rows() -> dict[str, list[str]]:
    """The class rows of results/fuzz.md (name -> cells), when its columns are this script's."""
    path = HERE / "results" / "fuzz.md"
    if not path.is_file():
        return {}
    lines = [ln for ln in path.read_text(encoding="utf-8").splitlines() if ln.startswith("| ")]
    if not lines or [c.strip() for c in lines[0].strip("|").split("|")][2:-1] != list(OUTCOMES):
        return {}
    rows = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in lines[1:]]
    return {r[0]: r for r in rows if r[0] != "**all classes**"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--examples", type=int, default=300, help="malformed inputs per class")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--slow-examples", type=int, default=40, help="malformed inputs per slow class")
    ap.add_argument("--only", default="", help="only classes whose name holds this text")
    ap.add_argument("--update", action="store_true", help="keep the other rows of results/fuzz.md")
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows, findings = [], []
    total: collections.Counter = collections.Counter()
    kept = _saved_rows() if args.update else {}
    for cls in fuzz_classes():
        if args.only and args.only not in cls.name:
            if cls.name in kept:
                rows.append(kept[cls.name])
                total.update(dict(zip(OUTCOMES, map(int, kept[cls.name][2:-1]), strict=True)))
            continue
        c, slowest, found = count(cls, args.slow_examples if cls.slow else args.examples, args.seed)
        total.update(c)
        findings += found
        n = sum(c.values())
        rows.append([cls.name, n, *(c[k] for k in OUTCOMES), f"{slowest:.2f}"])
        print(f"{cls.name}: {n} inputs, " + ", ".join(f"{k} {c[k]}" for k in OUTCOMES if c[k]), flush=True)
    n = sum(total.values())
    rows.append(["**all classes**", n, *(total[k] for k in OUTCOMES), ""])
    bad = n - sum(total[k] for k in HANDLED)
    notes = (
        f"{__doc__.split(chr(10) + chr(10))[1]}\n\n"
        f"{n} malformed inputs over {len(rows) - 1} classes in {time.perf_counter() - t0:.0f} s: "
        f"tracebacks {total['traceback']}, hangs {total['hang']}, non-zero exits without a message "
        f"{total['silent']}, late or no refusals {total['late']}, silently wrong {total['wrong']}, "
        f"internal errors {total['bug']}, messages not "
        f"naming the file {total['unnamed']}."
        + ("\n\nFindings:\n\n" + "\n".join(f"- `{f}`" for f in findings) if bad else "")
    )
    save(
        "fuzz",
        "Fuzzing the readers and commands: how malformed inputs end",
        ["input class", "inputs", *OUTCOMES, "slowest (s)"],
        rows,
        notes,
    )


if __name__ == "__main__":
    main()
