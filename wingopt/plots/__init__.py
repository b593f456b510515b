"""Figures written by the commands (matplotlib, Agg backend: no display needed)."""
