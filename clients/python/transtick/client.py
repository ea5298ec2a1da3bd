"""The client of the root's API (proto/cluster.proto, service transtick.v1.Root)."""

import dataclasses
import itertools
import json
import os
import queue
import threading
import time
from typing import Callable, Dict, Iterator, List, Optional, Union

import grpc
import numpy as np
from google.protobuf import json_format

import cluster_pb2
import cluster_pb2_grpc

# As the daemons: images and slabs travel in messages of up to 64 MiB.
_MAX_MESSAGE = 64 << 20
_ENDED = (cluster_pb2.DONE, cluster_pb2.FAILED, cluster_pb2.CANCELLED)


class JobFailed(Exception):
    """A job ended FAILED or CANCELLED; `state` and `job_id` say which."""

    def __init__(self, job_id: str, state: str, error: str):
        super().__init__(f"{job_id} {state.lower()}: {error}" if error else f"{job_id} {state.lower()}")
        self.job_id = job_id
        self.state = state
        self.error = error


class _Rows:
    """A frame's image as its chunks of rows come. It is whole when they cover
    its height; a row may come twice (a frame rendered again for a resuming
    watcher), with the same bits, and counts once."""

    def __init__(self) -> None:
        self.image: Optional[np.ndarray] = None
        self.have: Optional[np.ndarray] = None
        self.count = 0
        self.stats = None  # the first statistics seen with the frame's chunks

    def add(self, e_image, stats=None) -> bool:
        """Adds a chunk; True when the image is whole."""
        c = e_image
        self.image = _image(c, self.image)
        if self.have is None:
            self.have = np.zeros(c.height, dtype=bool)
        self.count += int(np.count_nonzero(~self.have[c.row_begin:c.row_end]))
        self.have[c.row_begin:c.row_end] = True
        if stats is not None and self.stats is None:
            self.stats = stats
        return self.count == c.height


@dataclasses.dataclass
class Frame:
    """One rendered frame of a job."""

    index: int  # over the job's views in order (dataset 0's, then dataset 1's, ...)
    dataset: int
    view: int
    image: np.ndarray  # float32, shape (height, width, 3), linear RGB as the renderer made it
    stats: dict  # ClusterFrameStats as JSON (docs/formats.md, "Cluster frame statistics")
    output: str  # the view's output path, as the job gave it ("" if none)

    def to_uint8(self) -> np.ndarray:
        """The image in 8 bits, as transtick writes a .png: clamped to [0, 1], x 255, rounded."""
        v = np.clip(self.image, np.float32(0), np.float32(1))
        return (v * np.float32(255) + np.float32(0.5)).astype(np.uint8)


def parse_job(job: Union[dict, str, "cluster_pb2.Job"], base_dir: str = ".") -> "cluster_pb2.Job":
    """A Job from a message, a dict or JSON text in the job file's schema.

    `materials_file` and `transfer_file` are read relative to `base_dir` and
    sent inline, as `transtick submit` does. Unknown fields are errors.
    """
    if isinstance(job, cluster_pb2.Job):
        message = cluster_pb2.Job()
        message.CopyFrom(job)
    else:
        message = cluster_pb2.Job()
        text = job if isinstance(job, str) else json.dumps(job)
        json_format.Parse(text, message)
    for dataset in message.datasets:
        for field, target in (("materials_file", dataset.materials), ("transfer_file", dataset.transfer)):
            name = getattr(dataset, field)
            if not name:
                continue
            path = name if os.path.isabs(name) else os.path.join(base_dir, name)
            with open(path, encoding="utf-8") as f:
                json_format.Parse(f.read(), target)
            dataset.ClearField(field)
    return message


def _message(value, cls):
    """A message of `cls` from a message, a dict or JSON text."""
    if isinstance(value, cls):
        return value
    message = cls()
    json_format.Parse(value if isinstance(value, str) else json.dumps(value), message)
    return message


def _image(chunk, image: Optional[np.ndarray]) -> np.ndarray:
    """Adds an ImageChunk's rows to `image` (made on the first chunk)."""
    c = chunk
    if c.width <= 0 or c.height <= 0 or c.width > 8192 or c.height > 8192:
        raise ValueError(f"the root sent an image chunk of an impossible size {c.width}x{c.height}")
    if image is None:
        image = np.zeros((c.height, c.width, 3), dtype=np.float32)
    rows = c.row_end - c.row_begin
    values = rows * c.width * 3
    # Rows as float32 (rgb) or RGB8 (rgb8), exactly one of them
    # (docs/formats.md, "Image chunks").
    float32 = len(c.rgb) == values * 4 and not c.rgb8
    rgb8 = len(c.rgb8) == values and not c.rgb
    if (image.shape != (c.height, c.width, 3) or c.row_begin < 0 or c.row_end > c.height
            or rows < 0 or not (float32 or rgb8)):
        raise ValueError("the root sent a malformed image chunk")
    if float32:
        block = np.frombuffer(c.rgb, dtype="<f4")
    else:
        # FromByte (image_io.h): b / 255 in float32, whose to_uint8 is b again.
        block = np.frombuffer(c.rgb8, dtype=np.uint8).astype(np.float32) / np.float32(255)
    image[c.row_begin:c.row_end] = block.reshape(rows, c.width, 3)
    return image


@dataclasses.dataclass
class SessionEvent:
    """What a session sends back (docs/formats.md, "Session stream")."""

    seq: int  # the request it answers
    ready: Optional[dict] = None  # SessionReady as JSON: the dataset is loaded
    image: Optional[np.ndarray] = None  # a whole frame, float32 (height, width, 3)
    preview: bool = False  # the frame is the coarse preview
    stats: Optional[dict] = None  # ClusterFrameStats as JSON, with a frame
    error: str = ""  # the request could not be done; the session goes on


class Session:
    """An interactive session: cameras and classifications out, frames back.

    Made by Client.session. set_view and the others may be called from any
    thread; next() from one thread at a time.
    """

    def __init__(self, stub, metadata, dataset, preview: int, image_encoding: str = "float32"):
        self._requests: "queue.Queue" = queue.Queue()
        self._seq = itertools.count(1)
        self._lock = threading.Lock()
        self._closed = False
        self._partial: Dict[tuple, _Rows] = {}
        # As a job's dataset: materials_file and transfer_file are read here.
        job = cluster_pb2.Job()
        job.datasets.append(_message(dataset, cluster_pb2.Dataset))
        encoding = cluster_pb2.ImageEncoding.Value(image_encoding.upper())
        self._send(cluster_pb2.SessionRequest(open=parse_job(job).datasets[0], preview=preview,
                                              image_encoding=encoding))
        self._responses = stub.Session(iter(self._requests.get, None), metadata=metadata)

    def _send(self, request) -> int:
        with self._lock:
            if self._closed:
                raise RuntimeError("the session is closed")
            request.seq = next(self._seq)
            self._requests.put(request)
            return request.seq

    def set_view(self, view) -> int:
        """A new camera (a View, or a dict of its fields); returns its seq."""
        return self._send(cluster_pb2.SessionRequest(view=_message(view, cluster_pb2.View)))

    def set_materials(self, materials) -> int:
        return self._send(cluster_pb2.SessionRequest(materials=_message(materials, cluster_pb2.MaterialSet)))

    def set_transfer(self, transfer) -> int:
        return self._send(cluster_pb2.SessionRequest(transfer=_message(transfer, cluster_pb2.TransferFunction)))

    def next(self) -> SessionEvent:
        """The next event: a ready notice, a whole frame, or an error.

        StopIteration when the session has ended; grpc.RpcError when the
        root ended it with an error (a bad open request, say).
        """
        for e in self._responses:
            if e.HasField("ready"):
                return SessionEvent(e.seq, ready=json_format.MessageToDict(e.ready, preserving_proto_field_name=True))
            if e.error:
                return SessionEvent(e.seq, error=e.error)
            if not e.HasField("image"):
                continue
            key = (e.seq, e.preview)
            rows = self._partial.setdefault(key, _Rows())
            if not rows.add(e.image, e.stats if e.HasField("stats") else None):
                continue
            del self._partial[key]
            stats = json_format.MessageToDict(rows.stats or e.stats, preserving_proto_field_name=True)
            return SessionEvent(e.seq, image=rows.image, preview=e.preview, stats=stats)
        raise StopIteration

    def frame(self, seq: int) -> SessionEvent:
        """Events until the full frame of `seq` (or a later one); an error event raises ValueError."""
        while True:
            e = self.next()
            if e.error and e.seq >= seq:
                raise ValueError(f"request {e.seq}: {e.error}")
            if e.image is not None and not e.preview and e.seq >= seq:
                return e

    def close(self) -> None:
        """Closes this side; returns when the root has answered every camera and ended."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._requests.put(None)
        try:
            while True:
                self.next()
        except StopIteration:
            pass

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def load_job(path: str) -> "cluster_pb2.Job":
    """A job file (docs/formats.md, "Job file"), with its files read inline."""
    with open(path, encoding="utf-8") as f:
        return parse_job(f.read(), os.path.dirname(os.path.abspath(path)))


class Client:
    """A connection to a transtick root.

    Without `ca` the channel is plaintext (the root allows that only on
    loopback). With `ca` (the cluster's CA certificate, a path), TLS, and the
    root's certificate must name `server_name`. `token` or `token_file` is the
    client's bearer token (docs/security.md).
    """

    def __init__(
        self,
        root: str,
        ca: Optional[str] = None,
        token: Optional[str] = None,
        token_file: Optional[str] = None,
        server_name: str = "transtick-root",
        timeout: float = 30.0,
    ):
        options = [
            ("grpc.max_receive_message_length", _MAX_MESSAGE),
            ("grpc.max_send_message_length", _MAX_MESSAGE),
        ]
        if token_file:
            with open(token_file, encoding="utf-8") as f:
                token = f.read().strip()
        if token and not ca:
            raise ValueError("a token is only sent over TLS: give ca= as well")
        if ca:
            with open(ca, "rb") as f:
                credentials = grpc.ssl_channel_credentials(root_certificates=f.read())
            options.append(("grpc.ssl_target_name_override", server_name))
            self._channel = grpc.secure_channel(root, credentials, options=options)
        else:
            self._channel = grpc.insecure_channel(root, options=options)
        self._stub = cluster_pb2_grpc.RootStub(self._channel)
        self._metadata = [("authorization", f"Bearer {token}")] if token else []
        self._timeout = timeout
        self.root = root

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def session(self, dataset, preview: int = 0, image_encoding: str = "float32") -> Session:
        """Opens an interactive session on `dataset` (a Dataset or a dict in the
        job file's schema, with exactly one view: the first camera); with
        `preview` (2 .. 16) each frame is preceded by one at 1/preview size.
        `image_encoding` "rgb8" brings the frames in 8 bits, a quarter of the
        bytes (their images are still float32: each byte / 255)."""
        return Session(self._stub, self._metadata, dataset, preview, image_encoding)

    def submit(self, job: Union[dict, str, "cluster_pb2.Job"]) -> str:
        """Queues a job; returns its id. Errors are grpc.RpcError naming the field."""
        reply = self._stub.Submit(parse_job(job), timeout=self._timeout, metadata=self._metadata)
        return reply.job_id

    def status(self) -> dict:
        """Workers, rings and the jobs this client may see (StatusReply as JSON)."""
        reply = self._stub.Status(cluster_pb2.StatusRequest(), timeout=self._timeout, metadata=self._metadata)
        return json_format.MessageToDict(reply, preserving_proto_field_name=True)

    def volumes(self) -> dict:
        """The volumes in the root's data directory and the presets (VolumesReply as JSON)."""
        reply = self._stub.Volumes(cluster_pb2.VolumesRequest(), timeout=self._timeout, metadata=self._metadata)
        return json_format.MessageToDict(reply, preserving_proto_field_name=True)

    def cancel(self, job_id: str) -> bool:
        """Cancels a job; False if it had already ended."""
        reply = self._stub.Cancel(cluster_pb2.JobRef(job_id=job_id), timeout=self._timeout, metadata=self._metadata)
        return reply.cancelled

    def frames(
        self,
        job_id: str,
        progress: Optional[Callable[[float, "cluster_pb2.JobEvent"], None]] = None,
        reconnect: float = 300.0,
    ) -> Iterator[Frame]:
        """Yields every frame of a job as it completes, to the job's end.

        Frames rendered before the call are delivered too. A stream that
        breaks is watched again with the frames already yielded, as the
        command-line client does, for up to `reconnect` seconds without news.
        `progress(fraction_of_job, event)` is called for progress events.
        Raises JobFailed when the job fails or is cancelled.
        """
        have: set = set()
        last_contact = time.monotonic()
        backoff = 0.25
        while True:
            request = cluster_pb2.WatchRequest(job_id=job_id, resume=True, have_frames=sorted(have))
            images: Dict[int, _Rows] = {}
            state, error = cluster_pb2.QUEUED, ""
            try:
                for e in self._stub.Watch(request, metadata=self._metadata):
                    last_contact = time.monotonic()
                    backoff = 0.25
                    state, error = e.state, e.error
                    if e.HasField("image"):
                        frame = None if e.frame in have else self._take_chunk(e, images)
                        if frame is not None and frame.index not in have:
                            have.add(frame.index)
                            yield frame
                    elif progress and e.pixels_total and e.frames_total:
                        done = (len(have) + e.pixels_done / e.pixels_total) / e.frames_total
                        progress(min(1.0, done), e)
            except grpc.RpcError as rpc:
                if rpc.code() not in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.CANCELLED):
                    raise
                if time.monotonic() - last_contact > reconnect:
                    raise
                time.sleep(backoff)
                backoff = min(backoff * 2, 2.0)
                continue
            if state in _ENDED:
                break
            time.sleep(backoff)  # the root stopped before the job ended
        if state != cluster_pb2.DONE:
            raise JobFailed(job_id, cluster_pb2.JobState.Name(state), error)

    def render(
        self,
        job: Union[dict, str, "cluster_pb2.Job"],
        progress: Optional[Callable[[float, "cluster_pb2.JobEvent"], None]] = None,
    ) -> List[Frame]:
        """Submits a job and returns its frames, in frame order."""
        job_id = self.submit(job)
        return sorted(self.frames(job_id, progress=progress), key=lambda f: f.index)

    @staticmethod
    def _take_chunk(e, images: Dict[int, "_Rows"]) -> Optional[Frame]:
        c = e.image
        rows = images.setdefault(e.frame, _Rows())
        if not rows.add(c, e.stats if e.HasField("stats") else None):
            return None
        del images[e.frame]
        stats = json_format.MessageToDict(rows.stats, preserving_proto_field_name=True) if rows.stats is not None else {}
        return Frame(index=e.frame, dataset=e.dataset, view=e.view, image=rows.image, stats=stats, output=c.output)
