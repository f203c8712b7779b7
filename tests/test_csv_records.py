"""Side files of named CSV columns (a marker table, a marker map) are read one way:
:func:`ingest.formats.text.read_csv_records`, so both readers say the same of the same
fault."""

from __future__ import annotations

import pytest

from animegraph.face.mesh import canonical_mesh, read_marker_map
from db.errors import DataError
from ingest.formats.text import read_csv_records
from ingest.readers.markers import read_marker_table


def test_records_have_their_line_and_stripped_cells(tmp_path):
    path = tmp_path / "m.csv"
    path.write_bytes("\ufeff Label ,GROUP,extra\nlm1, lips \n\nlm2,head,x\n".encode())
    names, rows = read_csv_records(path, "marker table", ("label", "group"))
    assert names == ["label", "group", "extra"]
    assert rows == [(f"{path}:2", {"label": "lm1", "group": "lips", "extra": ""}),
                    (f"{path}:4", {"label": "lm2", "group": "head", "extra": "x"})]


@pytest.mark.parametrize(("text", "message"), [
    ("label,other\nlm1,x\n", ":1: {what} needs 'label' and '{column}' columns, got"),
    ("", ":1: {what} needs 'label' and '{column}' columns, got []"),
    ("label,{column}\nlm1,{value}\nlm2,a\rb\n", ":3: malformed CSV"),  # the line it is on
    ("label,{column}\nlm1,{value}\nlm1,{value}\n", ":3: marker 'lm1' listed twice"),
])
def test_the_marker_table_and_the_marker_map_say_the_same_of_the_same_fault(tmp_path, text,
                                                                            message):
    readers = {"marker table": ("group", "lips", read_marker_table),
               "marker map": ("vertex", "1", lambda p: read_marker_map(p, canonical_mesh()))}
    for what, (column, value, read) in readers.items():
        path = tmp_path / f"{what}.csv"
        path.write_text(text.format(column=column, value=value))
        with pytest.raises(DataError) as caught:
            read(path)
        assert str(caught.value).startswith(str(path)), caught.value
        assert message.format(what=what, column=column) in str(caught.value), caught.value
