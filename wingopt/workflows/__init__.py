"""Workflows: use cases above the engines.

A workflow reads a problem, builds the models, runs the engines (:mod:`wingopt.control`,
:mod:`wingopt.estimation`) and hands what they return to :mod:`wingopt.results`, which owns every
file write. The command line parses arguments and calls a workflow; engines never write files.
"""
