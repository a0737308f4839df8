"""The ingest process's outbox to the server: newest wins when the server falls behind, losses counted."""

from __future__ import annotations

import multiprocessing as mp

from backend.ingest.live_ingest import _offer

OUTBOX_MESSAGES = 3
GET_TIMEOUT_S = 10.0  # the queue's feeder thread writes to its pipe within milliseconds; margin for a loaded machine


def test_a_full_outbox_loses_its_oldest_messages_and_counts_them() -> None:
    outbox = mp.get_context("spawn").Queue(OUTBOX_MESSAGES)
    tally = {"forward_dropped": 0}
    for i in range(10):  # the server reads nothing meanwhile
        _offer(outbox, ("batch", i), tally)
    received = [outbox.get(timeout=GET_TIMEOUT_S)[1] for _ in range(OUTBOX_MESSAGES)]
    assert received == [7, 8, 9]  # the server resumes at the present, in order
    assert tally["forward_dropped"] == 10 - OUTBOX_MESSAGES
    outbox.close()
