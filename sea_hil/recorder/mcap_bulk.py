"""Many MCAP messages per call: `BulkWriter.add_messages` appends a batch to the open chunk with one struct pack
per message, producing byte for byte what `mcap.writer.Writer.add_message` would (tests/test_recording_binary.py).

Why: the library's `add_message` builds a `Message` record object and writes it field by field through six struct
packs and two seeks, ~3.4 us per message on the 2-core host; the recorder writes ~8 messages per limb-sample at
1 kHz. The batch path updates the same statistics, chunk builder and message index the library keeps (its private
state, so `bulk_supported` says whether this mcap version still has them; without, `add_messages` falls back to
`add_message` one by one).
"""
from __future__ import annotations

import itertools
import struct
from collections.abc import Iterable

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import Writer

_HEAD = struct.Struct("<BQHIQQ")   # opcode, record length, channel id, sequence, log time, publish time
_FIXED = _HEAD.size - 9            # message record bytes after the 9-byte record header, before the data
_MESSAGE = int(Opcode.MESSAGE)
_INDEX_HEAD = struct.Struct("<BQHI")   # opcode, record length, channel id, entries length


class _MessageIndex(MessageIndex):
    """The library's message index, written with one pack for all its entries (its own `write` packs each entry's
    two numbers separately: ~1.5 us per message when the chunk is finished)."""

    def write(self, stream: RecordBuilder) -> None:
        n = len(self.records)
        stream.write(_INDEX_HEAD.pack(int(Opcode.MESSAGE_INDEX), 6 + 16 * n, self.channel_id, 16 * n))
        stream.write(struct.pack(f"<{2 * n}Q", *itertools.chain.from_iterable(self.records)))


class BulkWriter(Writer):
    """`mcap.writer.Writer` plus `add_messages`."""

    @property
    def bulk_supported(self) -> bool:
        cb = getattr(self, "_Writer__chunk_builder", None)
        return (cb is not None and hasattr(self, "_Writer__statistics") and hasattr(self, "_Writer__chunk_size")
                and hasattr(getattr(cb, "record_writer", None), "_buffer"))

    @property
    def chunk_count(self) -> int | None:
        """Chunks written so far (None if this mcap version keeps no statistics where this module looks)."""
        st = getattr(self, "_Writer__statistics", None)
        return None if st is None else int(st.chunk_count)

    def add_messages(self, items: Iterable[tuple[int, int, bytes, int, int]]) -> None:
        """Add (channel id, log time, data, publish time, sequence) messages in order, as `add_message` would;
        a chunk that grows past the chunk size is written out at once, as `add_message` does."""
        if not self.bulk_supported:
            for ch, log, data, pub, seq in items:
                self.add_message(ch, log, data, pub, seq)
            return
        st = self._Writer__statistics          # type: ignore[attr-defined]
        cb = self._Writer__chunk_builder       # type: ignore[attr-defined]
        limit: int = self._Writer__chunk_size  # type: ignore[attr-defined]
        counts, indices = st.channel_message_counts, cb.message_indices
        buf = cb.record_writer._buffer
        pack, write, tell = _HEAD.pack, buf.write, buf.tell
        for ch, log, data, pub, seq in items:
            if st.message_count == 0:
                st.message_start_time = log
            elif log < st.message_start_time:
                st.message_start_time = log
            if log > st.message_end_time:
                st.message_end_time = log
            counts[ch] += 1
            st.message_count += 1
            if cb.num_messages == 0:
                cb.message_start_time = log
            elif log < cb.message_start_time:
                cb.message_start_time = log
            if log > cb.message_end_time:
                cb.message_end_time = log
            index = indices.get(ch)
            if not index:
                index = indices[ch] = _MessageIndex(channel_id=ch, records=[])
            offset = tell()
            index.records.append((log, offset))
            cb.num_messages += 1
            write(pack(_MESSAGE, _FIXED + len(data), ch, seq, log, pub))
            write(data)
            if tell() > limit:
                self._Writer__finalize_chunk()   # type: ignore[attr-defined]
                buf = cb.record_writer._buffer   # the chunk builder starts a new buffer
                write, tell = buf.write, buf.tell
