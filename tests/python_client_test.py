"""The Python client (clients/python) against a real cluster of daemons.

Run by python_client_test.sh, which starts the daemons and passes the root's
address in TRANSTICK_ROOT, the data directory in TRANSTICK_TEST_DATA and the
transtick command in TRANSTICK_BIN.
"""

import os
import subprocess
import tempfile
import unittest

import grpc
import numpy as np
from PIL import Image

import transtick

ROOT = os.environ["TRANSTICK_ROOT"]
DATA = os.environ["TRANSTICK_TEST_DATA"]
BIN = os.environ["TRANSTICK_BIN"]
MATERIALS = {"materials": [{"name": "box", "min": 100, "max": 256, "color": [0.8, 0.7, 0.6]}]}


def job(views, **extra):
    return {"name": "python", "datasets": [{"volume": "box.nrrd", "materials": MATERIALS, "views": views}], **extra}


def view(azimuth, elevation=20, width=48, height=40, **extra):
    return {"azimuth": azimuth, "elevation": elevation, "width": width, "height": height, **extra}


class ClientTest(unittest.TestCase):
    def setUp(self):
        self.client = transtick.Client(ROOT)

    def tearDown(self):
        self.client.close()

    def test_frames_are_the_in_process_render(self):
        views = [view(35), view(120, -10, 32, 24, samples=4), view(200, 60, shadows=False)]
        progress = []
        frames = self.client.render(job(views), progress=lambda f, e: progress.append(f))
        self.assertEqual([f.index for f in frames], [0, 1, 2])
        with tempfile.TemporaryDirectory() as tmp:
            materials = os.path.join(tmp, "m.json")
            with open(materials, "w", encoding="utf-8") as f:
                import json
                json.dump(MATERIALS, f)
            for frame, v in zip(frames, views):
                self.assertEqual(frame.image.dtype, np.float32)
                self.assertEqual(frame.image.shape, (v["height"], v["width"], 3))
                self.assertGreater(frame.image.max(), 0.1, "the box is in view")
                self.assertEqual(frame.stats["width"], v["width"])
                out = os.path.join(tmp, f"ref{frame.index}.png")
                args = [BIN, "render", "--local", "0", "--quiet", "--volume", os.path.join(DATA, "box.nrrd"),
                        "--materials", materials, "--azimuth", str(v["azimuth"]), "--elevation",
                        str(v["elevation"]), "--size", f"{v['width']}x{v['height']}", "--out", out]
                if "samples" in v:
                    args += ["--samples", str(v["samples"])]
                if v.get("shadows") is False:
                    args += ["--shadows", "off"]
                subprocess.run(args, check=True)
                want = np.asarray(Image.open(out).convert("RGB"))
                np.testing.assert_array_equal(frame.to_uint8(), want, f"frame {frame.index}")
        self.assertTrue(all(0 <= p <= 1 for p in progress))

    def test_the_same_job_gives_the_same_floats(self):
        a = self.client.render(job([view(70)]))[0].image
        b = self.client.render(job([view(70)]))[0].image
        self.assertTrue(np.array_equal(a, b))

    def test_a_bad_job_is_refused_naming_the_field(self):
        with self.assertRaises(grpc.RpcError) as e:
            self.client.submit(job([view(0, width=0)]))
        self.assertEqual(e.exception.code(), grpc.StatusCode.INVALID_ARGUMENT)
        self.assertIn("datasets[0].views[0]", e.exception.details())
        with self.assertRaises(grpc.RpcError) as e:
            self.client.submit({"datasets": [{"volume": "../outside.nrrd", "materials": MATERIALS,
                                              "views": [view(0)]}]})
        self.assertIn(e.exception.code(), (grpc.StatusCode.INVALID_ARGUMENT, grpc.StatusCode.NOT_FOUND,
                                           grpc.StatusCode.PERMISSION_DENIED))
        from google.protobuf import json_format
        with self.assertRaises(json_format.ParseError):
            self.client.submit({"datasets": [], "no_such_field": 1})

    def test_volumes_lists_the_data_directory_and_the_presets(self):
        listing = self.client.volumes()
        self.assertIn("box.nrrd", [v["path"] for v in listing["volumes"]])
        self.assertIn("ct-bone", [p["name"] for p in listing["presets"]])

    def test_unknown_jobs_and_cancel(self):
        with self.assertRaises(grpc.RpcError) as e:
            list(self.client.frames("job-999999"))
        self.assertEqual(e.exception.code(), grpc.StatusCode.NOT_FOUND)
        job_id = self.client.submit(job([view(a, width=400, height=400, samples=16) for a in range(0, 360, 10)]))
        self.assertTrue(self.client.cancel(job_id))
        with self.assertRaises(transtick.JobFailed) as failed:
            list(self.client.frames(job_id))
        self.assertEqual(failed.exception.state, "CANCELLED")
        status = self.client.status()
        self.assertEqual(len(status["workers"]), 2)
        states = {j["job_id"]: j["state"] for j in status["jobs"]}
        self.assertEqual(states[job_id], "CANCELLED")

    def test_job_files_read_their_materials_inline(self):
        with tempfile.TemporaryDirectory() as tmp:
            with open(os.path.join(tmp, "m.json"), "w", encoding="utf-8") as f:
                import json
                json.dump(MATERIALS, f)
            with open(os.path.join(tmp, "job.json"), "w", encoding="utf-8") as f:
                json.dump({"datasets": [{"volume": "box.nrrd", "materials_file": "m.json",
                                         "views": [view(35)]}]}, f)
            loaded = transtick.load_job(os.path.join(tmp, "job.json"))
        self.assertEqual(loaded.datasets[0].materials.materials[0].name, "box")
        self.assertFalse(loaded.datasets[0].materials_file)
        frame = self.client.render(loaded)[0]
        np.testing.assert_array_equal(frame.image, self.client.render(job([view(35)]))[0].image)

    def test_a_session_renders_the_newest_camera(self):
        first = view(30)
        with self.client.session({"volume": "box.nrrd", "materials": MATERIALS, "views": [first]},
                                 preview=2) as s:
            ready = s.next()
            self.assertEqual(ready.ready["dims"], [24, 20, 16])
            preview = s.next()
            self.assertTrue(preview.preview)
            self.assertEqual(preview.image.shape, (20, 24, 3))
            full = s.frame(1)
            np.testing.assert_array_equal(full.image, self.client.render(job([first]))[0].image)
            seqs = [s.set_view(view(a)) for a in range(40, 400, 10)]
            got = []
            while not got or got[-1].seq != seqs[-1]:
                got.append(s.frame(seqs[0]))
            self.assertLess(len(got), len(seqs), "every stale camera was rendered")
            np.testing.assert_array_equal(got[-1].image, self.client.render(job([view(390)]))[0].image)
            bad = s.set_view(view(0, width=0))
            with self.assertRaises(ValueError) as e:
                s.frame(bad)
            self.assertIn("0x40", str(e.exception))
            again = s.set_view(view(55))
            self.assertEqual(s.frame(again).seq, again)

    def test_byte_jobs_and_sessions_give_the_bytes_of_the_float_frames(self):
        # RGB8 rows (docs/formats.md, "Image chunks"): each value is b / 255,
        # and to_uint8 gives back the bytes of the float frame.
        floats = self.client.render(job([view(35), view(120, -10, 32, 24)]))
        byte_frames = self.client.render(job([view(35), view(120, -10, 32, 24)], image_encoding="RGB8"))
        for f, b in zip(floats, byte_frames):
            self.assertEqual(b.image.dtype, np.float32)
            np.testing.assert_array_equal(b.to_uint8(), f.to_uint8())
            np.testing.assert_array_equal(b.image, f.to_uint8().astype(np.float32) / np.float32(255))
        first = view(30)
        with self.client.session({"volume": "box.nrrd", "materials": MATERIALS, "views": [first]},
                                 image_encoding="rgb8") as s:
            self.assertIsNotNone(s.next().ready)
            full = s.frame(1)
            want = self.client.render(job([first]))[0]
            np.testing.assert_array_equal(full.image, want.to_uint8().astype(np.float32) / np.float32(255))

    def test_tokens_need_tls(self):
        with self.assertRaises(ValueError):
            transtick.Client(ROOT, token="a-token-of-sixteen-chars")


class RowsTest(unittest.TestCase):
    """A frame's image from its chunks: whole only when they cover every row,
    however chunks of two renderings repeat and overlap."""

    def test_whole_only_when_covered(self):
        import random

        import cluster_pb2
        from transtick.client import _Rows

        rng = random.Random(5)
        for _ in range(500):
            w, h = rng.randint(1, 4), rng.randint(1, 20)
            truth = np.arange(h * w * 3, dtype="<f4").reshape(h, w, 3)
            stream = []
            for _ in range(rng.randint(1, 3)):
                y = 0
                while y < h:
                    end = min(h, y + rng.randint(1, max(1, h // 3)))
                    if rng.random() < 0.75:
                        stream.append(cluster_pb2.ImageChunk(width=w, height=h, row_begin=y, row_end=end,
                                                             rgb=truth[y:end].tobytes()))
                    y = end
            if rng.random() < 0.5:  # the same rows in RGB8
                for c in stream:
                    c.rgb8 = (np.frombuffer(c.rgb, dtype="<f4").astype(np.uint32) % 256).astype(np.uint8).tobytes()
                    c.ClearField("rgb")
                truth = (truth.astype(np.uint32) % 256).astype(np.float32) / np.float32(255)
            rows, covered = _Rows(), np.zeros(h, dtype=bool)
            for c in stream:
                whole = rows.add(c)
                covered[c.row_begin:c.row_end] = True
                self.assertEqual(whole, bool(covered.all()))
                if whole:
                    np.testing.assert_array_equal(rows.image, truth)
                    break


if __name__ == "__main__":
    unittest.main(verbosity=2)
