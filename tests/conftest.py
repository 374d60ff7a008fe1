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


@pytest.fixture
def f64():
    gs.init(precision="64", logging_level="warning")


@pytest.fixture
def f32():
    gs.init(precision="32", logging_level="warning")
