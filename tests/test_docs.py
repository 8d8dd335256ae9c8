"""Documentation generated from code stays current."""

from pathlib import Path

from sdmpi.config import schema_text


def test_job_keys_doc_matches_schema():
    doc = (Path(__file__).parents[1] / "docs" / "job_keys.md").read_text()
    assert schema_text().strip() in doc, "regenerate docs/job_keys.md (see its first lines)"
