"""Replays tests/fuzz_corpus/: every input that once ended in a traceback (or in a silent wrong
result) through the fuzzer's ``exercise``, expecting the outcome its index line names:
``ok``, ``error: TEXT`` (an AccumError containing TEXT) or ``warning: TEXT`` (runs through, a
warning containing TEXT). Regenerate with ``python benchmarks/fuzz.py --write-corpus tests/fuzz_corpus``."""

from __future__ import annotations

import importlib.util
import logging
from pathlib import Path

import pytest

from accumcli.errors import AccumError

CORPUS = Path(__file__).parent / "fuzz_corpus"
_spec = importlib.util.spec_from_file_location("fuzz", Path(__file__).parent.parent / "benchmarks" / "fuzz.py")
fuzz = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz)


def entries() -> list[tuple[str, str, str]]:
    rows = [line.split(" | ") for line in (CORPUS / "index.txt").read_text().splitlines() if line.strip()]
    return [(name, cls, outcome) for name, cls, outcome in rows]


def test_index_names_every_input_and_the_corpus_is_small():
    names = {name for name, _, _ in entries()}
    assert names == {p.name for p in CORPUS.glob("*.mcap")}
    assert len(names) == len(fuzz.CORPUS) >= 25
    assert sum(p.stat().st_size for p in CORPUS.iterdir()) < 2_000_000
    assert {cls[0] for _, cls, _ in entries() if cls[0].isdigit()} == set("12345678")


@pytest.mark.filterwarnings("error::RuntimeWarning")   # numpy's, which the fuzzer counts as foreign output
@pytest.mark.parametrize("name, cls, outcome", entries(), ids=[e[0] for e in entries()])
def test_corpus_input(name, cls, outcome, caplog, capfd, monkeypatch):
    monkeypatch.setattr(logging.getLogger("accumcli"), "handlers", [])  # the CLI's, if a CLI test ran before
    caplog.set_level(logging.WARNING, logger="accumcli")
    kind, _, text = outcome.partition(": ")
    if kind == "error":
        with pytest.raises(AccumError) as info:
            fuzz.exercise(str(CORPUS / name))
        assert text in str(info.value) and "\n" not in str(info.value)
    else:
        fuzz.exercise(str(CORPUS / name))
        if kind == "warning":
            assert text in caplog.text
        else:
            assert kind == "ok"
    assert capfd.readouterr().err == ""
