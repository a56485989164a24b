"""Write bags in the formats users have, from a ROS1 bag, with ``rosbags`` (tests and benchmarks).

- :func:`slice_ros1`: the first seconds of a ROS1 bag, topics renamed, chunks compressed (raw copy:
  the messages' bytes are unchanged).
- :func:`to_ros2`: a ROS 2 bag directory (``sqlite3`` or ``mcap`` storage, optional zstd
  compression), messages converted to the Humble typestore by ``rosbags.convert``.
- :func:`strip_definitions`: turn a ``sqlite3`` bag into what Foxy/Galactic/Humble's rosbag2 wrote:
  no ``message_definitions`` table, ``metadata.yaml`` version 4/5 without ``ros_distro`` or type
  hashes (Humble's sqlite3 plugin names the distribution in the ``.db3``'s schema table only).
"""

from __future__ import annotations

import sqlite3
from contextlib import closing
from pathlib import Path

from rosbags.convert import convert
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_typestore
from ruamel.yaml import YAML


def slice_ros1(
    src: Path,
    dst: Path,
    *,
    seconds: float,
    rename: dict[str, str] | None = None,
    compression: str | None = "bz2",
) -> None:
    """Copy the first ``seconds`` of ``src`` (all topics, ``rename`` applied) to a new ROS1 bag."""
    rename = rename or {}
    writer = Writer1(dst)
    if compression:
        writer.set_compression(Writer1.CompressionFormat[compression.upper()])
    with AnyReader([src]) as reader, writer:
        out = {}
        for c in reader.connections:
            ext = c.ext
            out[c.id] = writer.add_connection(
                rename.get(c.topic, c.topic),
                c.msgtype,
                msgdef=c.msgdef.data,
                md5sum=c.digest,
                callerid=getattr(ext, "callerid", None),
                latching=getattr(ext, "latching", None),
            )
        stop = reader.start_time + int(seconds * 1e9)
        for con, t, raw in reader.messages(stop=stop):
            writer.write(out[con.id], t, raw)


def to_ros2(src: Path, dst: Path, storage: str = "sqlite3", *, compress_mode: str | None = None) -> None:
    """Convert a ROS1 bag to a ROS 2 bag directory (messages as Humble types, definitions embedded).
    ``compress_mode``: None, ``"file"`` or ``"message"`` (zstd)."""
    convert(
        [src],
        dst,
        storage,
        8,
        "zstd" if compress_mode else None,
        compress_mode or "file",
        None,
        get_typestore(Stores.ROS2_HUMBLE),
        [],
        [],
        [],
        [],
    )


def strip_definitions(bag: Path, distro: str | None = "humble") -> None:
    """Remove the embedded message definitions of a ``sqlite3`` bag directory, as a pre-Jazzy
    rosbag2 would have written it. ``distro``: the name left in the ``.db3``'s schema table
    (Humble's layout), or None for none at all (Foxy's layout)."""
    for db in bag.glob("*.db3"):
        with closing(sqlite3.connect(db)) as con:
            con.execute("DROP TABLE IF EXISTS message_definitions")
            if distro:
                con.execute("UPDATE schema SET schema_version = 3, ros_distro = ?", (distro,))
            else:
                con.execute("DROP TABLE IF EXISTS schema")
            con.commit()
            con.execute("VACUUM")
    yml = YAML(typ="safe")
    meta_path = bag / "metadata.yaml"
    meta = yml.load(meta_path.read_text())
    info = meta["rosbag2_bagfile_information"]
    info["version"] = 5 if distro else 4
    info.pop("ros_distro", None)
    for t in info.get("topics_with_message_count", []):
        t["topic_metadata"].pop("type_description_hash", None)
    with meta_path.open("w") as f:
        YAML(typ="safe", pure=True).dump(meta, f)
