"""Convert the CYGNSS team's packet tables (team_tables/*.csv) into ccsdspy CSV definitions, one per APID.

Run from this folder: ``python convert_team_tables.py``. Writes ``ccsdspy/apidNNNNN.csv`` with the
4-column ccsdspy form ``name,data_type,bit_length,bit_offset`` plus a ``byte_order`` column taken from
the team's type code (``U21``/``F4321``: the first digit names the most significant octet, so a
descending order is little-endian). ccsdspy's CSV reader ignores ``byte_order`` (it reads every field
big-endian), and so does ``acs-twin ingest`` for these files: values are compared with ccsdspy's
reading of the same CSV. The primary-header rows (first 7) are left out, as ccsdspy expects.
Offsets come from the team's "Start Byte" / "Start Bit" (MSB = bit 0, CCSDS convention).
ENG_FILL (APID 391) gets no definition: every mnemonic of that flush packet contains "FILL", so it
holds no field (ccsdspy's own split test skips it for the same reason); its packet stays an
undefined APID, counted and kept raw by the ingest.
"""

import csv
from pathlib import Path

HERE = Path(__file__).parent
TYPES = {"U": "uint", "I": "int", "F": "float"}


def convert(table: Path, out: Path) -> None:
    """One team table -> one ccsdspy CSV."""
    with table.open(newline="") as f:
        rows = [{k.strip(): (v or "").strip() for k, v in r.items()} for r in csv.DictReader(f)]
    with out.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["name", "data_type", "bit_length", "bit_offset", "byte_order"])
        for r in rows[7:]:
            code, mnemonic = r["Type"], r["Mnemonic"]
            data_type = "fill" if "FILL" in mnemonic.upper() else TYPES[code[0]]
            little = len(code) > 2 and int(code[1]) > int(code[2])
            offset = 8 * int(r["Start Byte"]) + int(r["Start Bit"])
            writer.writerow([mnemonic, data_type, r["Data Size"], offset, "little" if little else "big"])


def main() -> None:
    with (HERE / "team_tables" / "Overview.csv").open(newline="") as f:
        overview = {r["Packet Short Name"]: int(r["APID_Decimal"]) for r in csv.DictReader(f)}
    (HERE / "ccsdspy").mkdir(exist_ok=True)
    for table in sorted((HERE / "team_tables").glob("*.csv")):
        if table.stem in overview and table.stem != "ENG_FILL":
            convert(table, HERE / "ccsdspy" / f"apid{overview[table.stem]:05d}.csv")


if __name__ == "__main__":
    main()
