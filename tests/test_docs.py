"""The manual stays current: docs generated from code match it, README.md and docs/ read as a
manual (no development history, papers by author and year)."""

import os
import re
from pathlib import Path

from sdmpi.config import schema_text


def test_job_keys_doc_matches_schema():
    doc = (Path(__file__).parents[1] / "docs" / "job_keys.md").read_text()
    assert schema_text().strip() in doc, "regenerate docs/job_keys.md (see its first lines)"


def test_manual_holds_no_development_history():
    """README.md and docs/ name papers by author and year (never "seed 00N", the random
    seed is job.seed) and leave development history (sessions, issues, commits) to git."""
    root = Path(__file__).parents[1]
    history = re.compile(r"\bseed[ -]00\d|\bsession \d|\bissue \d|\bcommit [0-9a-f]{7}", re.I)
    for path in [root / "README.md", *sorted((root / "docs").rglob("*.md"))]:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            assert not history.search(line), f"{path.relative_to(root)}:{number}: {line}"


def test_readme_is_a_front_page():
    assert len((Path(__file__).parents[1] / "README.md").read_text().splitlines()) <= 250


def test_scripts_the_manual_runs_are_executable():
    """The manual runs the scripts of postprocess/ and bench/ by their path
    (`postprocess/dratler1996.py ...`): every one with a #! line can be run that way."""
    root = Path(__file__).parents[1]
    for path in sorted([*(root / "postprocess").glob("*.py"), *(root / "bench").glob("*.py")]):
        if path.read_text().startswith("#!"):
            assert os.access(path, os.X_OK), f"chmod +x {path.relative_to(root)}"
