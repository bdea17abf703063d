"""ROS 1 bags and ROS 2 bag folders of ``dvs_msgs/EventArray`` messages, in chunks.

A ROS 2 bag is the folder holding ``metadata.yaml`` (or one of its ``.db3`` / ``.mcap``
files). rosbags reads the bag; the event arrays inside the messages are decoded with numpy,
since building one Python object per event (rosbags' deserialiser) is far slower.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from hybridneus.errors import RecordingError
from hybridneus.recordings.stream import CHUNK, EventChunk, EventSource, first_line, need

#: Message types whose layout is ``header, height, width, Event[] {x, y, ts, polarity}``.
EVENT_MSG_TYPES = ("dvs_msgs/msg/EventArray", "prophesee_event_msgs/msg/EventArray")

BAG_SUFFIXES = (".bag", ".db3", ".mcap")


class BagSource(EventSource):
    """ROS 1 bags and ROS 2 bag folders holding ``dvs_msgs/EventArray`` (the rpg_dvs_ros
    driver's, also used by Prophesee's ROS driver as ``prophesee_event_msgs/EventArray``).

    ``topic`` picks one event topic when a bag holds several. Event times are the events'
    own ``ts`` stamps (seconds), not the bag's receive times.
    """

    def __init__(self, path: Path, topic: str | None = None) -> None:
        if path.is_file() and path.suffix.lower() in (".db3", ".mcap"):
            path = path.parent
        self.path = path
        need("rosbags", path, "ROS bags")
        self._anyreader = importlib.import_module("rosbags.highlevel").AnyReader
        try:
            with self._anyreader([path]) as reader:
                self._ros2 = bool(reader.is2)
                connections = [(c.topic, c.msgtype) for c in reader.connections]
                first = None
                chosen = self._choose(connections, topic)
                for _, _, raw in reader.messages(
                        connections=[c for c in reader.connections if c.topic == chosen]):
                    first = _EventArrayLayout.decode(bytes(raw), self._ros2, path)
                    break
        except RecordingError:
            raise
        except Exception as exc:  # rosbags raises its own ReaderError and plain OSErrors
            raise RecordingError(f"{path}: cannot read as a ROS bag ({first_line(exc)})") \
                from None
        self._topic = chosen
        self.format = "ros2 bag" if self._ros2 else "ros1 bag"
        if first is not None and first[1] > 0 and first[2] > 0:
            self.size = (int(first[1]), int(first[2]))
        self.time_unit = "s"
        self.note = (f"{self.format}, topic {chosen}"
                     + (f", {self.size[0]}x{self.size[1]} from the messages" if self.size
                        else ""))

    def _choose(self, connections: list[tuple[str, str]], topic: str | None) -> str:
        events = sorted({t for t, m in connections if m in EVENT_MSG_TYPES})
        listing = ", ".join(f"{t} ({m})" for t, m in sorted(set(connections))) or "none"
        if topic is not None:
            types = {m for t, m in connections if t == topic}
            if not types:
                raise RecordingError(f"{self.path}: no topic {topic} (topics: {listing})")
            if not types & set(EVENT_MSG_TYPES):
                raise RecordingError(
                    f"{self.path}: topic {topic} holds {types.pop()}, expected one of "
                    f"{', '.join(EVENT_MSG_TYPES)}")
            return topic
        if not events:
            raise RecordingError(
                f"{self.path}: no event topic (dvs_msgs/EventArray) in the bag "
                f"(topics: {listing})")
        if len(events) > 1:
            raise RecordingError(
                f"{self.path}: several event topics ({', '.join(events)}); pick one with "
                "--topic")
        return events[0]

    def chunks(self) -> Iterator[EventChunk]:
        parts: list[EventChunk] = []
        held = 0
        try:
            with self._anyreader([self.path]) as reader:
                conns = [c for c in reader.connections if c.topic == self._topic]
                for _, _, raw in reader.messages(connections=conns):
                    chunk = _EventArrayLayout.decode(bytes(raw), self._ros2, self.path)[0]
                    if len(chunk):
                        parts.append(chunk)
                        held += len(chunk)
                    if held >= CHUNK:
                        yield EventChunk.concatenate(parts)
                        parts, held = [], 0
        except RecordingError:
            raise
        except Exception as exc:
            raise RecordingError(f"{self.path}: reading the bag failed ({first_line(exc)})") \
                from None
        if parts:
            yield EventChunk.concatenate(parts)


class _EventArrayLayout:
    """Decodes one serialised EventArray message with numpy.

    ROS 1 packs each event in 13 bytes. ROS 2's CDR aligns each field to its size from the
    start of the payload, so the first event (which starts 4-aligned after the array's
    length) takes 14 bytes and every later one 16 (two bytes of padding before ``ts``);
    the message may end in up to 3 bytes of padding.
    """

    ROS1 = np.dtype({"names": ["x", "y", "sec", "nsec", "pol"],
                     "formats": ["<u2", "<u2", "<u4", "<u4", "u1"],
                     "offsets": [0, 2, 4, 8, 12], "itemsize": 13})
    CDR_FIRST = np.dtype({"names": ["x", "y", "sec", "nsec", "pol"],
                          "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
                          "offsets": [0, 2, 4, 8, 12], "itemsize": 14})
    CDR_REST = np.dtype({"names": ["x", "y", "sec", "nsec", "pol"],
                         "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
                         "offsets": [0, 2, 6, 10, 14], "itemsize": 16})

    @classmethod
    def decode(cls, raw: bytes, ros2: bool, path: Path) -> tuple[EventChunk, int, int]:
        """(events, width, height) of one message."""
        try:
            if ros2:
                if raw[:2] != b"\x00\x01":
                    raise ValueError("not little-endian CDR")
                body = raw[4:]
                o = 8  # stamp
                (n_id,) = np.frombuffer(body, "<u4", 1, o)
                o = _align(o + 4 + int(n_id), 4)
                height, width, n = (int(v) for v in np.frombuffer(body, "<u4", 3, o))
                o += 12
                if n == 0:
                    rec = np.zeros(0, cls.CDR_FIRST)
                    end = o
                else:
                    first = np.frombuffer(body + b"\x00", cls.CDR_FIRST, 1, o)
                    rest = np.frombuffer(body + b"\x00", cls.CDR_REST, n - 1, o + 14)
                    rec = (first, rest)
                    end = o + 13 if n == 1 else o + 14 + 16 * (n - 2) + 15
            else:
                body = raw
                o = 12  # seq, stamp
                (n_id,) = np.frombuffer(body, "<u4", 1, o)
                o += 4 + int(n_id)
                height, width, n = (int(v) for v in np.frombuffer(body, "<u4", 3, o))
                o += 12
                rec = np.frombuffer(body, cls.ROS1, n, o)
                end = o + 13 * n
            # rclcpp pads a serialised message to a multiple of 4 bytes; rosbags' own
            # deserialiser allows the same up-to-3 bytes after the last field.
            left = len(body) - end
            if left < 0 or (left > (3 if ros2 else 0)):
                raise ValueError(f"{left} bytes left over" if left > 0 else
                                 f"{-left} bytes missing")
        except ValueError as exc:
            raise RecordingError(
                f"{path}: an event message does not decode as EventArray ({exc})") from None
        if isinstance(rec, tuple):
            rec = np.concatenate([rec[0].astype(cls.CDR_REST), rec[1]])
        t = rec["sec"].astype(np.float64) + rec["nsec"].astype(np.float64) * 1e-9
        chunk = EventChunk(t, rec["x"].astype(np.int32), rec["y"].astype(np.int32),
                           rec["pol"] != 0)
        return chunk, width, height


def _align(offset: int, size: int) -> int:
    return (offset + size - 1) // size * size


__all__ = ["BAG_SUFFIXES", "BagSource", "EVENT_MSG_TYPES"]
