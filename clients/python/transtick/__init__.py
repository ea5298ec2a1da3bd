"""transtick: a Python client of the transtick render service.

    import transtick
    client = transtick.Client("127.0.0.1:7000")           # or ca=..., token=...
    frames = client.render(transtick.load_job("examples/cthead_job.json"))
    frames[0].image                                       # numpy float32, (height, width, 3)

The API is the root's gRPC service (proto/cluster.proto); the protobuf
messages are in transtick.v1 (Job, View, Dataset, ...).
"""

import os as _os
import sys as _sys

# The generated modules import each other by their bare names.
_sys.path.insert(0, _os.path.join(_os.path.dirname(__file__), "_proto"))

import types as _types  # noqa: E402

import cluster_pb2 as _cluster_pb2  # noqa: E402
import transtick_pb2 as _transtick_pb2  # noqa: E402

# The API's messages and enums, as the package transtick.v1 of the protos.
v1 = _types.ModuleType("transtick.v1")
for _module in (_transtick_pb2, _cluster_pb2):
    for _name in dir(_module):
        if not _name.startswith("_"):
            setattr(v1, _name, getattr(_module, _name))

from .client import (  # noqa: E402,F401
    Client,
    Frame,
    JobFailed,
    Session,
    SessionEvent,
    load_job,
    parse_job,
)

__all__ = ["Client", "Frame", "JobFailed", "Session", "SessionEvent", "load_job", "parse_job", "v1"]
