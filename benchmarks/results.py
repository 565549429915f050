"""The benchmarks' saved tables: one source for every figure the docs quote.

A benchmark run whose tables the docs show is saved, with the command that printed it, the
machine, the date and the commit, as benchmarks/results/NAME.txt:

    nice python benchmarks/results.py save speed_batch -- python benchmarks/bench_speed.py --tables batch

runs the command (printing its output as it goes) and writes the file. Its text is then
quoted two ways, and test/project/test_figures.py fails when either disagrees with the file:

- a whole table, between `<!-- generated: results/NAME -->` and `<!-- end generated -->`
  in a page: `scripts/reference` writes it there (the command, the machine and the output);
- one figure in prose, followed by `<!-- figure: NAME "ROW" COLUMN -->`: the number written
  just before the marker must be the saved value, rounded as written. ROW is the first
  words of the output line, COLUMN the 1-based field after them, split on spaces.

File format: `key: value` lines (command, machine, date, commit, note), a line `---`, then
the output exactly as printed.
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDER = ROOT / "benchmarks" / "results"
KEYS = ("command", "machine", "date", "commit", "note")
FIGURE = re.compile(r"(?P<number>[-+]?[0-9][0-9 ,]*(?:\.[0-9]+)?(?:e[-+]?[0-9]+)?)"
                    r"(?P<unit>[×x%]?)<!-- figure: (?P<name>[\w.-]+) \"(?P<row>[^\"]+)\" "
                    r"(?P<column>[0-9]+) -->")
NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:e[-+]?[0-9]+)?")


@dataclass
class Result:
    name: str
    command: str
    machine: str
    date: str
    commit: str
    note: str
    output: str

    def row(self, label: str) -> list:
        """The fields after `label` on the first output line that starts with its words
        (however many spaces a table puts between them)."""
        words = label.split()
        for line in self.output.splitlines():
            fields = line.split()
            if fields[:len(words)] == words:
                return fields[len(words):]
        raise KeyError(f"results/{self.name}: no line starts with {label!r}")

    def figure(self, label: str, column: int) -> str:
        """The field COLUMN (1-based) of the row `label`, as printed."""
        fields = self.row(label)
        if not 1 <= column <= len(fields):
            raise KeyError(f"results/{self.name}: row {label!r} has {len(fields)} fields, "
                           f"not {column}")
        return fields[column - 1]


def path(name: str) -> Path:
    return FOLDER / f"{name}.txt"


def names() -> list:
    return sorted(p.stem for p in FOLDER.glob("*.txt"))


def load(name: str) -> Result:
    text = path(name).read_text(encoding="utf-8")
    head, _, output = text.partition("\n---\n")
    values = dict.fromkeys(KEYS, "")
    for line in head.splitlines():
        key, _, value = line.partition(": ")
        if key not in KEYS:
            raise ValueError(f"{path(name)}: unknown key {key!r} (keys: {', '.join(KEYS)})")
        values[key] = value
    return Result(name, output=output.rstrip("\n"), **values)


def save(name: str, command: str, output: str, note: str = "") -> Path:
    values = {"command": command, "machine": machine(), "date": datetime.date.today().isoformat(),
              "commit": commit(), "note": note}
    head = "".join(f"{key}: {values[key]}\n" for key in KEYS if values[key])
    FOLDER.mkdir(exist_ok=True)
    path(name).write_text(f"{head}---\n{output.rstrip()}\n", encoding="utf-8")
    return path(name)


def machine() -> str:
    """Cores, CPU model, OS and how busy the machine was (its load average at the save)."""
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            model = next((line.split(":", 1)[1].strip() for line in cpuinfo
                          if line.startswith("model name")), model)
    except OSError:
        pass
    try:
        load = f", load average {os.getloadavg()[0]:.1f} at the end"
    except OSError:
        load = ""
    return (f"{os.cpu_count()} CPUs ({model}), {platform.system()} {platform.machine()}, "
            f"Python {platform.python_version()}{load}")


def commit() -> str:
    """The checkout's commit, `+changes` when its tracked files differ from it."""
    def git(*args):
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)
    head = git("rev-parse", "--short=7", "HEAD")
    if head.returncode != 0:
        return "unknown"
    dirty = git("diff", "--quiet", "HEAD", "--", ".", ":(exclude)benchmarks/results").returncode
    return head.stdout.strip() + (" +changes" if dirty else "")


def render(name: str) -> str:
    """A saved run as a page shows it: what printed it, where and when, then its output."""
    r = load(name)
    where = f"on {r.machine}, {r.date}, at {r.commit}" if r.date else f"on {r.machine}"
    note = f" {r.note}" if r.note else ""
    return (f"`{r.command}` {where} (`benchmarks/results/{name}.txt`).{note}\n\n"
            f"```text\n{r.output}\n```\n")


def written_equals(written: str, value: str) -> bool:
    """Is `written` (a figure as a page writes it: 1 035, 8.7, 4.1e-06) the printed
    `value` rounded as written?"""
    found = NUMBER.match(value.replace(",", ""))
    if not found:
        return False
    number, text = float(found.group()), written.replace(" ", "").replace(" ", "").replace(",", "")
    if "e" in text:
        mantissa = text.split("e")[0].lstrip("+-")
        digits = len(mantissa.replace(".", "").lstrip("0")) or 1
        return float(f"{number:.{digits - 1}e}") == float(text)
    decimals = len(text.split(".")[1]) if "." in text else 0
    return abs(number - float(text)) <= 0.5 * 10.0 ** -decimals * (1 + 1e-9)


def figures(text: str) -> list:
    """[(written, name, row, column)] of every figure marker in a page's text."""
    return [(m["number"].strip(), m["name"], m["row"], int(m["column"]))
            for m in FIGURE.finditer(text)]


def wrong_figures(text: str, where: str) -> list:
    """One line per figure in `text` that its saved output does not bear out."""
    wrong = []
    for written, name, row, column in figures(text):
        try:
            value = load(name).figure(row, column)
        except (OSError, KeyError) as error:
            wrong.append(f"{where}: {written} <- results/{name} {row!r} {column}: {error}")
            continue
        if not written_equals(written, value):
            wrong.append(f"{where}: {written} where results/{name} {row!r} column {column} "
                         f"printed {value}")
    return wrong


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    ours, command = (argv[:argv.index("--")], argv[argv.index("--") + 1:]) if "--" in argv \
        else (argv, [])
    parser = argparse.ArgumentParser(description="run a benchmark and save its output as "
                                                 "benchmarks/results/NAME.txt",
                                     usage="%(prog)s save NAME [--note TEXT] -- COMMAND ...")
    sub = parser.add_subparsers(dest="what", required=True)
    run = sub.add_parser("save", help="run COMMAND, print and save its output")
    run.add_argument("name", help="the results file's name (letters, digits, _ . -)")
    run.add_argument("--note", default="", help="a sentence the page shows after the command")
    args = parser.parse_args(ours)
    if not command or not re.fullmatch(r"[\w.-]+", args.name):
        parser.error("give a NAME of letters, digits, _ . - and, after --, the command")
    done = subprocess.run(command, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    sys.stdout.write(done.stdout)
    if done.returncode != 0:
        print(f"results: {' '.join(command)} exited {done.returncode}; nothing saved",
              file=sys.stderr)
        return done.returncode
    program = "python" if Path(command[0]).name.startswith("python") else command[0]
    shown = " ".join((["nice"] if os.nice(0) > 0 else []) + [program, *command[1:]])
    print(f"results: wrote {save(args.name, shown, done.stdout, args.note)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
