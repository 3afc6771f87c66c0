#!/usr/bin/env python3
"""Check an ONNX export (`l3p export --format onnx`) against numpy_policy.py with onnxruntime.

    python3 test_onnx.py <policy.onnx or its dir> <safetensors export dir or policy.safetensors>

The model must pass `onnx.checker` (with shape inference), declare `obs` [batch, obs_dim] ->
`actions` [batch, action_dim] float32, carry the export's JSON config under metadata `l3p_export`,
and compute the action means numpy_policy.act computes from the safetensors export (max abs
difference < 1e-5 on random observations). Prints `skipped: ...` and passes when onnx or
onnxruntime is not installed (pip install onnx onnxruntime). Run by `infer/tests/onnx_runtime.rs`.
"""
import json
import sys
import unittest
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

ONNX_PATH = None
SAFETENSORS_PATH = None
TOLERANCE = 1e-5


class OnnxExportTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        if ONNX_PATH is None:
            raise unittest.SkipTest("run as a script: python3 test_onnx.py <policy.onnx> <export dir>")
        import numpy_policy

        cls.model = onnx.load(str(ONNX_PATH))
        cls.config, cls.tensors = numpy_policy.load(SAFETENSORS_PATH)
        cls.act = staticmethod(lambda obs: numpy_policy.act(cls.config, cls.tensors, obs))
        cls.session = ort.InferenceSession(str(ONNX_PATH), providers=["CPUExecutionProvider"])

    def test_checker_accepts_the_model(self):
        onnx.checker.check_model(self.model, full_check=True)
        self.assertEqual(self.model.ir_version, 8)
        self.assertEqual(self.model.producer_name, "l3p")
        opsets = {o.domain: o.version for o in self.model.opset_import}
        self.assertEqual(opsets, {"": 17})

    def test_metadata_holds_the_export_config(self):
        meta = {p.key: p.value for p in self.model.metadata_props}
        self.assertEqual(json.loads(meta["l3p_export"]), self.config)
        self.assertIn("io", self.config)
        self.assertEqual(int(meta["obs_dim"]), self.config["obs_dim"])
        self.assertEqual(int(meta["action_dim"]), self.config["action_dim"])
        self.assertEqual(meta["robot"], self.config["robot"])
        self.assertEqual(meta["format"], self.config["format"])
        std = self.tensors[self.config["std"]]
        np.testing.assert_array_equal(np.asarray(json.loads(meta["action_std"]), dtype=np.float32), std)

    def test_io_names_and_shapes(self):
        (inp,) = self.session.get_inputs()
        (out,) = self.session.get_outputs()
        self.assertEqual((inp.name, inp.shape, inp.type), ("obs", ["batch", self.config["obs_dim"]], "tensor(float)"))
        self.assertEqual(
            (out.name, out.shape, out.type), ("actions", ["batch", self.config["action_dim"]], "tensor(float)")
        )

    def test_actions_match_numpy_policy(self):
        rng = np.random.default_rng(0)
        worst = 0.0
        for batch, scale in [(1, 1.0), (7, 1.0), (256, 1.0), (64, 3.0)]:
            obs = (rng.standard_normal((batch, self.config["obs_dim"])) * scale).astype(np.float32)
            (got,) = self.session.run(["actions"], {"obs": obs})
            expected = self.act(obs)
            self.assertEqual(got.shape, (batch, self.config["action_dim"]))
            self.assertEqual(got.dtype, np.float32)
            diff = float(np.max(np.abs(got - expected)))
            worst = max(worst, diff)
            self.assertLess(diff, TOLERANCE, f"batch {batch}, obs scale {scale}")
        print(f"onnxruntime {ort.__version__} vs numpy_policy: max abs diff {worst:.3g}", file=sys.stderr)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    try:
        import numpy as np
        import onnx
        import onnxruntime as ort
    except ImportError as e:
        print(f"skipped: {e.name} is not installed (pip install numpy onnx onnxruntime)")
        sys.exit(0)
    ONNX_PATH = Path(sys.argv[1])
    if ONNX_PATH.is_dir():
        ONNX_PATH = ONNX_PATH / "policy.onnx"
    SAFETENSORS_PATH = Path(sys.argv[2])
    unittest.main(argv=sys.argv[:1], verbosity=2)
