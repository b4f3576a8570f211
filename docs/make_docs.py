"""Regenerate the generated parts of the documentation.

Usage: python docs/make_docs.py [--check] [--samples]

Between ``<!-- generated: NAME -->`` and ``<!-- end generated -->`` a page holds
a table derived from the code's own declarations (the objective's terms and
the ``[optimize]`` settings); between ``<!-- sample: COMMAND -->`` and
``<!-- end sample -->`` the console output of ``tendon-taichi COMMAND``, run in
a temporary folder. ``--check`` rewrites nothing and exits with status 1 when a
generated table is out of date (the test suite runs it); ``--samples`` also
runs the sample commands again (slow: it optimizes) and records the commit.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
BLOCK = re.compile(r"(<!-- generated: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- end generated -->)", re.S)
SAMPLE = re.compile(r"(<!-- sample: (?P<cmd>[^>]+?) -->\n)(?P<body>.*?)(<!-- end sample -->)", re.S)


def settings_table() -> str:
    """Every key of a scene's ``[optimize]`` table, with its default, unit and admissible values."""
    from tendon_taichi.objective.settings import SETTINGS
    from tendon_taichi.objective.terms import registered

    owner = {s.name: t.name for t in registered() for s in t.settings}
    rows = ["| key | default | unit | values | flag | what it is |", "|---|---|---|---|---|---|"]
    for s in SETTINGS:
        rows.append(f"| `{s.key}` | `{s.default!r}` | {s.unit or '-'} | {s.bounds_text() or '-'} | `{s.flag}` | "
                    f"{s.text}{f' (term `{owner[s.name]}`)' if s.name in owner else ''} |")
    return "\n".join(rows) + "\n"


def terms_table() -> str:
    """Every term of the objective, in the order the objective sums them."""
    from tendon_taichi.objective.terms import registered

    rows = ["| term | settings | acts on | stages | on a realizable robot | what it is |",
            "|---|---|---|---|---|---|"]
    for t in registered():
        keys = ", ".join(f"`{s.name}`" for s in t.settings) or "-"
        doc = " ".join((t.__doc__ or "").split()).replace("``", "`").replace("|", "\\|")
        rows.append(f"| `{t.name}` | {keys} | {'union tension' if t.union else 'each pose'} | "
                    f"{'homotopy stages (1, 2, ...)' if t.homotopy else 'every stage'} | "
                    f"{'no' if t.lattice else 'yes'} | {doc} |")
    return "\n".join(rows) + "\n"


GENERATORS = {"optimize-settings": settings_table, "objective-terms": terms_table}


def _commit() -> str:
    r = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    return r.stdout.strip() or "unknown"


def run_sample(cmd: str) -> str:
    """The console output of ``tendon-taichi CMD`` (stdout), run in a temporary folder."""
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run([sys.executable, "-m", "tendon_taichi", *cmd.split()], cwd=tmp, capture_output=True,
                           text=True, timeout=1800)
    if r.returncode not in (0, 4):
        raise SystemExit(f"sample '{cmd}' failed ({r.returncode}): {r.stderr.strip()[-500:]}")
    return (f"```console\n$ tendon-taichi {cmd}\n{r.stdout.rstrip()}\n```\n"
            f"<sub>(made by `python docs/make_docs.py --samples` at commit {_commit()})</sub>\n")


def regenerate(text: str, samples: bool) -> str:
    text = BLOCK.sub(lambda m: m.group(1) + GENERATORS[m.group("name")]() + m.group(4), text)
    if samples:
        text = SAMPLE.sub(lambda m: m.group(1) + run_sample(m.group("cmd").strip()) + m.group(4), text)
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only check that the generated tables are current")
    ap.add_argument("--samples", action="store_true", help="also run the sample commands again")
    args = ap.parse_args(argv)
    stale = []
    for page in sorted(HERE.glob("*.md")) + [ROOT / "README.md"]:
        text = page.read_text()
        new = regenerate(text, args.samples and not args.check)
        if new != text:
            stale.append(page.name)
            if not args.check:
                page.write_text(new)
    if args.check and stale:
        print(f"out of date: {', '.join(stale)} (run python docs/make_docs.py)", file=sys.stderr)
        return 1
    print(("rewrote " + ", ".join(stale)) if stale and not args.check else "docs are current")
    return 0


if __name__ == "__main__":
    sys.exit(main())
