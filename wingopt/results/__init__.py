"""Results: atomic output directories, JSON/CSV writers, plots and reports."""

from wingopt.results.writer import (
    ResultDirectory,
    check_file_writable,
    check_writable,
    to_jsonable,
    write_csv,
    write_json,
    write_text_atomic,
)

__all__ = [
    "ResultDirectory",
    "check_file_writable",
    "check_writable",
    "to_jsonable",
    "write_csv",
    "write_json",
    "write_text_atomic",
]
