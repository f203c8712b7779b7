"""A one-shot ``synth`` imports only what it uses (issue 17): what makes that so.

Load-independent evidence of the start-up work: the heavy libraries a ``synth`` run
leaves out of ``sys.modules``, and the light replacements giving the same values.
"""

import json
import shutil
import subprocess
import sys

import numpy as np
import pyarrow as pa
import pyarrow.dataset as ds
import pytest

from animegraph.synthesis import Model
from db.arrow import numbers, repeat_string
from db.store import PARTITIONED, TABLES, Database, _read_parts
from ingest.decompose import MotionDecomposer
from ingest.emotion.mapping import EmotionMapping
from ingest.unmixing import Unmixing

#: Heavy libraries other commands use, which a one-shot synth does not need to import.
HEAVY = ("sklearn", "scipy.signal", "scipy.stats", "scipy.interpolate", "scipy.spatial",
         "scipy.fft", "pandas", "pyarrow.dataset", "librosa", "duckdb")


def test_one_shot_synth_imports_no_heavy_library(tiny_db, tiny_corpus, tmp_path):
    clip = sorted((tiny_corpus / "clips").glob("*_happy_1.wav"))[0]
    wav = tmp_path / "speech.wav"
    shutil.copy(clip, wav)
    shutil.copy(clip.with_name(clip.stem + ".phones.csv"), tmp_path / "speech.phones.csv")
    code = (
        "import json, sys\n"
        "from animegraph.apps.cli import main\n"
        f"status = main(['synth', {str(wav)!r}, '--db', {str(tiny_db[0])!r}, '--emotion', "
        f"'happy', '-o', {str(tmp_path / 'out.c3d')!r}])\n"
        f"print(json.dumps([status, [m for m in {HEAVY!r} if m in sys.modules]]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    status, loaded = json.loads(out.stdout.strip().splitlines()[-1])
    assert status == 0 and (tmp_path / "out.c3d").exists()
    assert loaded == []


@pytest.mark.parametrize("array", [
    pa.array([1.5, -2.0, 3.25]), pa.array([1, 2, 3], pa.int32()),
    pa.array([1, 255, 3], pa.uint8()), pa.array([1.0, 2.0, 3.0, 4.0], pa.float32()).slice(1, 2),
    pa.array([7, 8, 9], pa.int64()).slice(2), pa.array([], pa.float64()),
    pa.chunked_array([pa.array([1, 2], pa.int16()), pa.array([3], pa.int16())]),
])
def test_numbers_equal_to_numpy(array):
    ours = numbers(array)
    theirs = array.to_numpy()
    assert ours.dtype == theirs.dtype
    np.testing.assert_array_equal(ours, theirs)


def test_numbers_with_nulls():
    array = pa.array([4, None, 6, None], pa.int64()).slice(1)
    np.testing.assert_array_equal(numbers(array, null=-1), [-1, 6, -1])
    np.testing.assert_array_equal(numbers(array), array.to_numpy(zero_copy_only=False))
    with pytest.raises(TypeError, match="not a numeric column"):
        numbers(pa.array(["a"]))


def test_repeat_string():
    assert repeat_string("happy", 3).equals(pa.array(["happy"] * 3, pa.string()))
    assert repeat_string("x", 0).equals(pa.array([], pa.string()))


def test_tables_read_without_pyarrow_dataset_are_the_same(tiny_db):
    db = Database.open(tiny_db[0])
    for name in TABLES:
        path = db.table_path(name)
        dataset = ds.dataset(path, format="parquet",
                             partitioning="hive" if name in PARTITIONED else None)
        expected = dataset.to_table()
        got = _read_parts(path, None, name in PARTITIONED)
        assert got.equals(expected) and got.schema.equals(expected.schema), name
        columns = [expected.column_names[-1], expected.column_names[0]]
        assert _read_parts(path, columns, name in PARTITIONED).equals(
            dataset.to_table(columns=columns)), name
        assert _read_parts(path, ["no such column"], name in PARTITIONED) is None


def test_restored_models_transform_as_the_estimators(tiny_db, rng):
    model = Model.load(tiny_db[0])
    arrays = model.db.arrays()
    assert type(model.decomposer) is Unmixing
    estimator = MotionDecomposer.from_arrays(arrays)
    motion = rng.normal(size=(50, len(model.names))) + estimator.mean_
    np.testing.assert_array_equal(model.decomposer.transform(motion), estimator.transform(motion))
    ics = rng.normal(size=(50, model.decomposer.n_pcs_))
    np.testing.assert_array_equal(model.decomposer.inverse_transform(ics),
                                  estimator.inverse_transform(ics))
    for key, light in model.emotion_model.mappings.items():
        prefix = f"emotion/map/{key[0]}/{key[1]}/"
        fitted = EmotionMapping.from_arrays({k[len(prefix):]: v for k, v in arrays.items()
                                             if k.startswith(prefix)})
        e = rng.normal(size=(40, light.centres_.shape[1]))
        np.testing.assert_allclose(light.transform(e), fitted.transform(e), rtol=1e-12,
                                   atol=1e-12)


def test_info_imports_no_heavy_library(tiny_db):
    code = (
        "import json, sys\n"
        "from animegraph.apps.cli import main\n"
        f"status = main(['info', '--db', {str(tiny_db[0])!r}])\n"
        f"print(json.dumps([status, [m for m in {HEAVY!r} if m in sys.modules]]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == [0, []]
