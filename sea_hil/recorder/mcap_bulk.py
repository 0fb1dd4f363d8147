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
from collections.abc import Sequence

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

    def add_messages(self, items: Sequence[tuple[int, int, bytes, int, int]]) -> None:
        """Add (channel id, log time, data, publish time, sequence) messages in order, as `add_message` would;
        a chunk that grows past the chunk size is written out at once, as `add_message` does. The messages up to
        a chunk's end go into its buffer in one write, and the statistics take each run's earliest and latest log
        time once."""
        if not self.bulk_supported:
            for ch, log, data, pub, seq in items:
                self.add_message(ch, log, data, pub, seq)
            return
        st = self._Writer__statistics          # type: ignore[attr-defined]
        cb = self._Writer__chunk_builder       # type: ignore[attr-defined]
        limit: int = self._Writer__chunk_size  # type: ignore[attr-defined]
        counts, indices, pack = st.channel_message_counts, cb.message_indices, _HEAD.pack
        i, n = 0, len(items)
        while i < n:
            buf = cb.record_writer._buffer
            pos = start = buf.tell()
            parts: list[bytes] = []
            put = parts.append
            first = i
            lo = hi = items[i][1]
            for ch, log, data, pub, seq in itertools.islice(items, i, None):
                i += 1
                if log < lo:
                    lo = log
                elif log > hi:
                    hi = log
                counts[ch] += 1
                index = indices.get(ch)
                if not index:
                    index = indices[ch] = _MessageIndex(channel_id=ch, records=[])
                index.records.append((log, pos))
                size = _FIXED + len(data)
                put(pack(_MESSAGE, size, ch, seq, log, pub))
                put(data)
                pos += 9 + size
                if pos > limit:
                    break
            buf.write(b"".join(parts))
            assert buf.tell() == pos, (start, pos)
            k = i - first
            st.message_start_time = lo if st.message_count == 0 else min(lo, st.message_start_time)
            st.message_end_time = max(hi, st.message_end_time)
            st.message_count += k
            cb.message_start_time = lo if cb.num_messages == 0 else min(lo, cb.message_start_time)
            cb.message_end_time = max(hi, cb.message_end_time)
            cb.num_messages += k
            if pos > limit:
                self._Writer__finalize_chunk()   # type: ignore[attr-defined]
