"""Numbers in names: a recording's key is its file name's stem, whatever the lux level or speed factor."""

from pathlib import PurePosixPath

import pytest

from simspad.dataset.directory import recording_rel_path
from simspad.io.names import number_label, recording_key


@pytest.mark.parametrize("lux, k", [(1, 1), (10000, 16), (0.5, 2.5), (1e6, 1), (2e7, 64), (0.001, 0.25),
                                    (123456789, 1), (1 / 3, 3)])
def test_recording_key_is_the_file_stem(lux, k):
    stem = PurePosixPath(recording_rel_path("office", lux, k)).stem
    assert recording_key("office", lux, k) == stem


def test_number_labels_map_back_to_one_value():
    for x in (1.0, 16.0, 0.5, 1e6, 1e-5, 1 / 3, 123456789.0, 2.5):
        assert float(number_label(x)) == x
    assert number_label(1e6) == "1000000" and number_label(16.0) == "16" and number_label(0.5) == "0.5"
