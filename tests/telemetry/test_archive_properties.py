"""Property test: any split of a packet stream into shuffled, overlapping, repeated uploads archives the set union.

Truth: the archive holds each distinct (time, sequence count) packet exactly once, in time order,
whatever the order, overlap and repetition of the uploads that carried it (issue 5: duplicates
rejected idempotently, out-of-order data accepted and ordered).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from telemetry.archive import Archive, PacketBatch

N_PACKETS = 200
T0_NS = 1_750_000_000 * 10**9
SAT = "PROP"
_databases = itertools.count()

uploads_strategy = st.lists(
    st.lists(st.integers(min_value=0, max_value=N_PACKETS - 1), min_size=1, max_size=120),
    min_size=1,
    max_size=6,
)


def stream() -> PacketBatch:
    """N_PACKETS packets at 2 Hz whose value is their index."""
    i = np.arange(N_PACKETS)
    packets = [int(k).to_bytes(2, "big") * 5 for k in i]
    return PacketBatch.from_packets(42, T0_NS + i * 500_000_000, i, packets, {"v": i.astype(np.float64)})


@settings(max_examples=30, deadline=None)
@given(uploads=uploads_strategy)
def test_any_mix_of_uploads_archives_each_packet_once_in_time_order(tmp_path_factory, uploads: list[list[int]]) -> None:
    whole = stream()
    path: Path = tmp_path_factory.mktemp("prop") / f"a{next(_databases)}.sqlite"
    with Archive(f"sqlite:///{path}") as archive:
        accepted = sum(
            archive.ingest(SAT, [whole.take(np.array(idx))], source=f"u{k}", uploaded_by="hypothesis").packets_accepted
            for k, idx in enumerate(uploads)
        )
        union = np.unique(np.concatenate([np.array(idx) for idx in uploads]))
        t, v = archive.read_parameter(SAT, "v", T0_NS, T0_NS + 10**12)
        replayed = [p for _, p in archive.replay(SAT, T0_NS, T0_NS + 10**12)]
    assert accepted == union.size
    np.testing.assert_array_equal(v, union.astype(np.float64))
    np.testing.assert_array_equal(t, whole.t_utc_ns[union])
    assert replayed == [whole.packets()[k] for k in union]
