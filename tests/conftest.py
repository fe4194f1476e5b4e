"""Shared fixtures: small simulated recordings, made once per test session."""

from __future__ import annotations

import logging

import pytest

from accumcli.simulation import SimulationOptions, simulate


@pytest.fixture(autouse=True)
def _propagate_accum_logs():
    """The CLI detaches accum's logger from the root; let caplog see it in every test."""
    logger = logging.getLogger("accumcli")
    logger.propagate = True
    logger.setLevel(logging.WARNING)
    yield


@pytest.fixture(autouse=True)
def _no_interrupt_from_an_earlier_test():
    """The interrupts a test sent this process stay in its ``outputs`` record (``interrupt_received``),
    which turns any later error into 'interrupted': each test starts without them."""
    from accumcli import outputs

    outputs._received.clear()
    outputs._pending.clear()
    yield


def _make(tmp_path_factory, name: str, **options) -> str:
    path = tmp_path_factory.mktemp("rec") / f"{name}.mcap"
    simulate(str(path), SimulationOptions(**options))
    return str(path)


@pytest.fixture(scope="session")
def small_recording(tmp_path_factory) -> str:
    return _make(tmp_path_factory, "small", frames=6, width=320, height=240, seed=11)


@pytest.fixture(scope="session")
def raw_recording(tmp_path_factory) -> str:
    return _make(tmp_path_factory, "raw", frames=4, width=640, height=480, seed=12, raw=True, shape="prism")


@pytest.fixture(scope="session")
def fisheye_recording(tmp_path_factory) -> str:
    return _make(tmp_path_factory, "fisheye", frames=4, width=640, height=480, seed=12, raw=True, shape="prism",
                 distortion="fisheye")


@pytest.fixture(scope="session")
def tf_tree_recording(tmp_path_factory) -> str:
    return _make(tmp_path_factory, "tftree", frames=5, width=320, height=240, seed=13, tf_tree=True,
                 shape="house")


@pytest.fixture(scope="session")
def noisy_pair(tmp_path_factory) -> tuple[str, str]:
    """The same 16-frame recording with exact and with noisy (1.5 deg, 4 mm) gripper poses."""
    common = dict(frames=16, width=640, height=480, seed=31)
    return (_make(tmp_path_factory, "exact", **common),
            _make(tmp_path_factory, "noisy", pose_noise_deg=1.5, pose_noise_m=0.004, **common))
