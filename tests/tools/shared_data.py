"""Where ../shared/data is for the Python tests: beside the repository, or $LODSTREAM_SHARED_DATA.

A test calls shared_data_dir(source); when the data is absent it has printed the "skipped:" line that ctest
looks for (SKIP_REGULAR_EXPRESSION) and gets None back.
"""
import os


def shared_data_dir(source):
    data = os.environ.get("LODSTREAM_SHARED_DATA") or os.path.join(source, "..", "shared", "data")
    if not os.path.isdir(data):
        print("skipped: ../shared/data is absent (set LODSTREAM_SHARED_DATA to run this test)")
        return None
    return data
