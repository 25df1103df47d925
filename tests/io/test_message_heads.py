"""Reading only the heads of large messages (wolfcal.io.message_heads) against mcap's own reader, and its
switch."""

from __future__ import annotations

import random

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from wolfcal.io import message_heads
from wolfcal.io.message_heads import iter_message_heads


def _mixed_file(path, compression: str) -> None:
    """Messages of three topics, log times out of order across and within chunks, some equal; big ones of many
    sizes."""
    rng = random.Random(3)
    with path.open("wb") as handle:
        writer = Writer(handle, chunk_size=3000, compression=CompressionType[compression.upper()])
        writer.start()
        schema = writer.register_schema("s", "raw", b"")
        big, small, other = (writer.register_channel(t, "raw", schema) for t in ("/big", "/small", "/other"))
        for k in range(200):
            channel = rng.choice([big, small, other])
            size = rng.choice([0, 5, 100, 2000]) if channel == big else 8
            writer.add_message(channel, log_time=rng.randrange(50), data=bytes([k % 256]) * size, publish_time=0)
        writer.finish()


def _heads_and_expected(path):
    with path.open("rb") as handle:
        reader = make_reader(handle)
        expected = [(c.topic, m.log_time, m.data) for _, c, m in reader.iter_messages(topics=["/big", "/small"])]
        heads = list(iter_message_heads(reader, handle, ["/big", "/small"], {"/big"}, 50, lambda _, head: head[0] % 2))
    return heads, expected


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_message_heads_come_as_iter_messages_gives_them(tmp_path, compression):
    """The messages of `iter_messages` in its order, of the head topics only the first bytes when they are
    enough; compressed chunks whole."""
    path = tmp_path / "mixed.mcap"
    _mixed_file(path, compression)
    heads, expected = _heads_and_expected(path)
    assert [(h.channel.topic, h.message.log_time) for h in heads] == [e[:2] for e in expected]
    for head, (topic, _, data) in zip(heads, expected, strict=True):
        short = compression == "none" and topic == "/big" and len(data) > 50 and data[0] % 2
        assert head.complete == (not short)
        assert head.message.data == (data[:50] if short else data)


def test_switched_off_every_message_is_read_whole_by_mcap(tmp_path, monkeypatch):
    path = tmp_path / "mixed.mcap"
    _mixed_file(path, "none")
    monkeypatch.setattr(message_heads, "ENABLED", False)
    heads, expected = _heads_and_expected(path)
    assert all(h.complete for h in heads)
    assert [(h.channel.topic, h.message.log_time, h.message.data) for h in heads] == expected
