"""Pack a run's log as a study record: a JSON or JSON-lines file gzipped, every float rounded to 6
significant digits (the records are read for curves and tables; 16-digit floats doubled their size,
and the tracked tree is what a GPU visit carries), without a name or time in the gzip header, so an
unchanged log packs byte for byte.

Usage:
  pack_record.py SRC DST.gz [--from-iteration K]   SRC plain or gzipped; JSON lines from iteration K
  pack_record.py --in-place RECORD.gz...           repack committed records
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import sys
from pathlib import Path
from typing import Any

DIGITS = 6


def rounded(value: Any) -> Any:
    """``value`` with every float in it rounded to :data:`DIGITS` significant digits."""
    if isinstance(value, float):
        return float(f"{value:.{DIGITS}g}")
    if isinstance(value, dict):
        return {k: rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [rounded(v) for v in value]
    return value


def read_text(path: Path) -> str:
    data = path.read_bytes()
    return (gzip.decompress(data) if data[:2] == b"\x1f\x8b" else data).decode()


def packed(text: str, lines: bool, from_iteration: int | None = None) -> str:
    """The rounded text: JSON lines (rows before ``from_iteration`` left out) or one document."""
    if not lines:
        return json.dumps(rounded(json.loads(text))) + "\n"
    rows = [json.loads(line) for line in text.splitlines() if line.strip()]
    if from_iteration is not None:
        rows = [r for r in rows if r.get("iteration", from_iteration) >= from_iteration]
    return "".join(json.dumps(rounded(r)) + "\n" for r in rows)


def write_gz(path: Path, text: str) -> None:
    """Gzip ``text`` to ``path`` (mtime 0, no name: deterministic), through a temporary file."""
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as gz:
        gz.write(text.encode())
    os.replace(tmp, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", type=Path)
    parser.add_argument("--in-place", action="store_true", help="repack each RECORD.gz")
    parser.add_argument("--from-iteration", type=int, default=None)
    args = parser.parse_args(argv)
    if args.in_place:
        jobs = [(p, p) for p in args.paths]
    elif len(args.paths) == 2:
        jobs = [(args.paths[0], args.paths[1])]
    else:
        parser.error("give SRC DST.gz, or --in-place RECORD.gz...")
    for src, dst in jobs:
        lines = src.name.removesuffix(".gz").endswith(".jsonl")
        if args.from_iteration is not None and not lines:
            parser.error(f"--from-iteration applies to JSON lines (*.jsonl), not {src}")
        if not dst.parent.is_dir():
            parser.error(f"{dst.parent} does not exist; give DST.gz in an existing folder")
        try:
            out = packed(read_text(src), lines, args.from_iteration)
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            print(
                f"pack_record: {src} is not a readable JSON or JSON-lines log ({err})",
                file=sys.stderr,
            )
            return 1
        write_gz(dst, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
