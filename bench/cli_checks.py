"""Argument checks shared by the benchmark scripts: a bad value is refused by argparse before
anything is measured (a benchmark that crashed after minutes of measuring lost them all).

Each ``*_type`` function is an argparse ``type=``: it returns the converted value or raises
``argparse.ArgumentTypeError`` with the reason, which argparse prints with the option's name.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path


def _number(kind: type, test: Callable[[float], bool], what: str) -> Callable[[str], float]:
    def convert(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None
        if not (math.isfinite(value) and test(value)):
            raise argparse.ArgumentTypeError(f"{text!r} is not {what}")
        return value
    convert.__name__ = what  # argparse names the type in its messages
    return convert


positive_int = _number(int, lambda x: x >= 1, "an integer >= 1")
non_negative_int = _number(int, lambda x: x >= 0, "an integer >= 0")
positive_float = _number(float, lambda x: x > 0, "a finite number > 0")
non_negative_float = _number(float, lambda x: x >= 0, "a finite number >= 0")
finite_float = _number(float, lambda x: True, "a finite number")


def output_folder(ap: argparse.ArgumentParser, path: Path, option: str = "--out") -> Path:
    """``path`` made absolute, or ``ap.error`` when it exists and is not a folder (or cannot
    be one: a file on its way)."""
    path = path.expanduser().resolve()
    for p in (path, *path.parents):
        if p.exists():
            if not p.is_dir():
                ap.error(f"{option} {path}: {p} is not a folder")
            break
    return path


def output_stem(ap: argparse.ArgumentParser, path: Path, option: str = "--out") -> Path:
    """``path`` made absolute for outputs named ``<stem>.json`` and ``<stem>.png`` beside it
    (``sibling(stem, '.json')``), or ``ap.error`` when its folder is not one."""
    path = path.expanduser().resolve()
    output_folder(ap, path.parent, option)
    return path


def sibling(stem: Path, suffix: str) -> Path:
    """``<stem><suffix>``: ``a.v2`` -> ``a.v2.json`` (``with_suffix`` made it ``a.json``)."""
    return stem.parent / (stem.name + suffix)


def refuse_duplicates(ap: argparse.ArgumentParser, values: list, option: str) -> None:
    """``ap.error`` naming the values given more than once."""
    twice = sorted({v for v in values if values.count(v) > 1}, key=str)
    if twice:
        ap.error(f"{option}: {', '.join(map(str, twice))} given more than once")
