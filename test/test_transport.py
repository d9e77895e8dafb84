"""The nodes' Fast DDS profile (ros.transport): what it sets, and that a user's profile wins."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from rta_attitude.ros import transport

NS = "{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}"


def test_the_profile_is_a_default_writer_profile_that_sets_only_a_tenth_of_a_second_heartbeat() -> None:
    root = ET.parse(transport.profile_path()).getroot()
    writers = root.findall(f"{NS}data_writer")
    assert len(writers) == 1 and writers[0].get("is_default_profile") == "true"
    assert len(root) == 1  # no participant, transport or reader profile: nothing else of Fast DDS changes
    (times,) = list(writers[0])
    assert times.tag == f"{NS}times"
    (period,) = list(times)
    assert period.tag == f"{NS}heartbeatPeriod"
    sec, nanosec = (int(period.find(f"{NS}{k}").text) for k in ("sec", "nanosec"))  # type: ignore[union-attr]
    assert sec + nanosec * 1e-9 == pytest.approx(0.1)


def test_use_profile_sets_ours_only_where_the_user_named_none(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    for k in transport.PROFILE_ENVS:  # setenv first: monkeypatch then restores the variable's absence too
        monkeypatch.setenv(k, "")
        monkeypatch.delenv(k)
    assert transport.use_profile()
    assert Path(os.environ[transport.PROFILE_ENV]).samefile(transport.profile_path())
    for k in transport.PROFILE_ENVS:
        monkeypatch.delenv(transport.PROFILE_ENV, raising=False)
        mine = str(tmp_path / "mine.xml")
        monkeypatch.setenv(k, mine)
        assert not transport.use_profile()
        assert os.environ[k] == mine
        monkeypatch.delenv(k)
