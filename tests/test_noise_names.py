"""One noise convention, the unit in the name (issue 26): the demo's and compare's configs take
``noise_fraction`` / ``noise_fractions``; the former ``noise`` / ``noises`` still work and warn."""

from __future__ import annotations

import dataclasses
import warnings

import pytest

from wingopt.errors import InputError
from wingopt.workflows.comparison import ComparisonPreset
from wingopt.workflows.demo import DemoConfig


def test_demo_config_noise_fraction_and_its_deprecated_alias():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert DemoConfig().noise_fraction == 0.01
        cfg = DemoConfig(noise_fraction=0.05)
        assert dataclasses.replace(cfg, seed=3).noise_fraction == 0.05  # replace keeps it, without a warning
    with pytest.warns(FutureWarning, match="use noise_fraction"):
        assert DemoConfig(noise=0.02) == DemoConfig(noise_fraction=0.02)
    with pytest.raises(InputError, match="noise_fraction"):
        DemoConfig(noise_fraction=1.5)


def test_comparison_preset_noise_fractions_and_its_deprecated_alias():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert ComparisonPreset().noise_fractions == (0.01, 0.05)
        assert dataclasses.replace(ComparisonPreset(noise_fractions=(0.02,)), seeds=2).noise_fractions == (0.02,)
    with pytest.warns(FutureWarning, match="use noise_fractions"):
        assert ComparisonPreset(noises=(0.03,)).noise_fractions == (0.03,)
