"""Results: atomic output directories, JSON/CSV writers, plots and reports."""

from wingopt.results.writer import ResultDirectory, check_writable, to_jsonable, write_csv, write_json

__all__ = ["ResultDirectory", "check_writable", "to_jsonable", "write_csv", "write_json"]
