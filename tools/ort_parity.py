#!/usr/bin/env python3
"""Checks rlnav's ONNX exports with software rlnav did not write: onnx.checker (full check)
and ONNX Runtime, whose outputs must match rlnav's own forward pass.

Usage: ort_parity.py CASE.json... where each case names a model, observations (one per step;
a recurrent model carries its state from step to step, starting at zero) and the expected `mu`
per step. Written by crates/policy/tests/onnx_export.rs.
"""
import json
import sys

import numpy as np
import onnx
import onnxruntime as ort


def check(case_path):
    case = json.load(open(case_path))
    model = onnx.load(case["model"])
    onnx.checker.check_model(model, full_check=True)
    meta = {p.key: p.value for p in model.metadata_props}
    assert "rlnav.contract" in meta, "contract missing from metadata_props"
    assert model.opset_import[0].version >= 14
    sess = ort.InferenceSession(case["model"], providers=["CPUExecutionProvider"])
    names = [i.name for i in sess.get_inputs()]
    outs = [o.name for o in sess.get_outputs()]
    for want in case.get("outputs", ["mu", "log_std", "value"]):
        assert want in outs, f"output {want} missing: {outs}"
    state = {}
    if case["recurrent"]:
        assert names == ["obs", "out_state.1", "hidden_state.1"], names
        units = sess.get_inputs()[1].shape[2]
        state = {n: np.zeros((1, 1, units), np.float32) for n in names[1:]}
    worst = 0.0
    for obs, mu in zip(case["obs"], case["mu"]):
        feed = {"obs": np.asarray([obs], np.float32), **state}
        res = dict(zip(outs, sess.run(None, feed)))
        worst = max(worst, float(np.max(np.abs(res["mu"][0] - np.asarray(mu, np.float32)))))
        if "log_std" in res:
            assert res["log_std"].shape == res["mu"].shape
        if case["recurrent"]:
            state = {"out_state.1": res["out_state"], "hidden_state.1": res["hidden_state"]}
    ok = worst <= case["tolerance"]
    print(f"{case['model']}: onnx.checker ok, onnxruntime {ort.__version__}, {len(case['obs'])} steps, "
          f"max |mu - rlnav| = {worst:.2e} ({'ok' if ok else 'FAIL'})")
    return ok


if __name__ == "__main__":
    results = [check(p) for p in sys.argv[1:]]
    sys.exit(0 if all(results) else 1)
