"""Shared fixtures: runtime precision and the robots we test on."""
import os

import pybullet_data
import pytest

import genesis_lite as gs

ASSETS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "assets")
PYBULLET = pybullet_data.getDataPath()


def asset(*parts):
    return os.path.join(ASSETS, *parts)


def pybullet(*parts):
    return os.path.join(PYBULLET, *parts)


FIRST = ("test_examples.py",)  # the longest file (each example a subprocess, ~20 s): started first


def pytest_collection_modifyitems(items):
    """Run FIRST's tests before the rest (order otherwise kept): the suite runs on two workers,
    one file to a worker (pyproject's addopts), and a long file dealt out last would run alone
    at the end."""
    items.sort(key=lambda item: os.path.basename(str(item.fspath)) not in FIRST)


@pytest.fixture
def f64():
    gs.init(precision="64", logging_level="warning")


@pytest.fixture
def f32():
    gs.init(precision="32", logging_level="warning")
