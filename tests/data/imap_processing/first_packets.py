"""Copy the first N CCSDS packets of a packet file, walking the packet length fields (CCSDS 133.0-B-2 §4.1.3.5).

python first_packets.py SOURCE N DESTINATION
"""

import sys
from pathlib import Path


def first_packets(data: bytes, n: int) -> bytes:
    """The octets of the first n whole packets of a clean packet stream (fewer if it holds fewer)."""
    end = 0
    for _ in range(n):
        if end + 6 > len(data):
            break
        size = ((data[end + 4] << 8) | data[end + 5]) + 7
        if end + size > len(data):
            break
        end += size
    return data[:end]


if __name__ == "__main__":
    source, n, destination = sys.argv[1:4]
    Path(destination).write_bytes(first_packets(Path(source).read_bytes(), int(n)))
