"""bench.json's ``stream`` section (bench/stream*.py) on the session's tiny
flightlog-min export: the replay's timings split by what each push did, the stream object's size
per target, and the report section."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from quadfdi.bench.report_stream import stream_report
from quadfdi.bench.stream import stream_section
from quadfdi.formats.dataset import flights_by_class
from quadfdi.bench.stream_memory import limit_macros
from quadfdi.formats.export_folder import Export
from quadfdi.formats.dataset import load_dataset
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)


@pytest.fixture(scope="module")
def section(flightlog_export, host_build):  # noqa: F811
    export = Export.open(flightlog_export)
    return stream_section(flightlog_export.parent, export, str(host_build / "fwref_infer"), "0", 1,
                          log=lambda _: None, cores=("cortex-m4",)), export


def test_stream_flights_round_robin_over_test_classes(flightlog_export):
    ds = load_dataset(flightlog_export.parent / "dataset.npz")
    rows = flights_by_class(ds, 3)
    test = [i for i, s in enumerate(ds["split_names"]) if str(s) == "test"]
    assert len(rows) == 3 and np.isin(ds["split"][rows], test).all()
    assert len(set(ds["fault_class"][rows].tolist())) == min(3, len(set(ds["fault_class"][np.isin(ds["split"], test)])))


def test_every_push_is_timed_once_and_decisions_cost_more(section, flightlog_export):
    s, _ = section
    ds = load_dataset(flightlog_export.parent / "dataset.npz")
    samples = ds["telemetry"].shape[1] * len(s["flights"])
    assert [(r["model"], r["precision"]) for r in s["latency"]] == [
        ("cnode", "fp32"), ("cnode", "int8"), ("gru", "fp32"), ("gru", "int8")]
    for r in s["latency"]:
        assert r["push_n"] + r["decision_n"] + r["other_strides"] == samples
        strides = len(s["flights"]) * ((ds["telemetry"].shape[1] - s["window"]) // s["stride"] + 1)
        assert 0 < r["decision_n"] <= strides and r["decision_n"] + r["other_strides"] == strides
        assert 0 < r["push_p50_us"] <= r["push_p99_us"] and r["decision_p50_us"] <= r["decision_max_us"]
        assert r["decision_p50_us"] > r["push_p50_us"]  # a decision runs a model, a push copies one sample


def test_stream_object_size_per_target(section, flightlog_export):
    s, export = section
    mem = {m["target"]: m for m in s["memory"]}
    lim = limit_macros(export.onboard(), export)
    assert lim["FWREF_MAX_CHANNELS"] == export.manifest["n_channels"] and lim["FWREF_MAX_ALARM_N"] == max(
        export.policy(net)[0]["n"] for net in ("cnode", "gru"))
    w, c = lim["FWREF_MAX_WINDOW"], lim["FWREF_MAX_CHANNELS"]
    host = mem["host"]["stream_bytes"]
    assert host >= 2 * 4 * w * c + w  # ring and window (float32) and the ok flags, at least
    assert host < mem["host"]["fwref_stream_build_bytes"]  # the program's generous limits hold more
    if shutil.which("arm-none-eabi-g++"):
        assert 2 * 4 * w * c + w <= mem["cortex-m4"]["stream_bytes"] <= host  # 32-bit pointers, same buffers
    else:
        assert "not found" in mem["cortex-m4"]["skipped"]


def test_report_section_lists_every_model_and_target(section):
    s, _ = section
    text = "\n".join(stream_report({"stream": s}))
    assert text.count("| cnode |") == 2 and text.count("| gru |") == 2 and "| host |" in text
    assert stream_report({}) == []
    assert "Not measured: why" in "\n".join(stream_report({"stream": {"skipped": "why"}}))
