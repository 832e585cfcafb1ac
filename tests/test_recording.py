"""Recording loader: formats, column mapping and scale, one-line errors for bad files."""
import numpy as np
import pytest

from servo.errors import RecordingError
from servo.io.recording import load_recording, parse_mapping, save_recording_csv
from tests.helpers import EMPS_MAT


def write_csv(path, header, rows):
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")
    return path


def good_rows(n=100, dt=1e-3):
    t = np.arange(n) * dt
    return np.column_stack([t, np.sin(t), np.cos(t), -np.sin(t)])


def test_csv_npz_round_trip(tmp_path):
    rows = good_rows()
    rec = load_recording(write_csv(tmp_path / "r.csv", ["t", "u", "x", "v"], rows))
    assert rec.n == 100 and rec.dt == pytest.approx(1e-3) and np.array_equal(rec.v, rows[:, 3])
    save_recording_csv(tmp_path / "s.csv", rec)
    again = load_recording(tmp_path / "s.csv")
    assert np.array_equal(again.x, rec.x)
    np.savez(tmp_path / "r.npz", t=rows[:, 0], u=rows[:, 1], x=rows[:, 2])
    rec2 = load_recording(tmp_path / "r.npz")
    assert rec2.v is None and np.array_equal(rec2.u, rows[:, 1])


def test_emps_mat_with_mapping_and_scale():
    rec = load_recording(EMPS_MAT, columns=parse_mapping("u=vir,x=qm", "--columns"), scale={"u": "gtau"})
    assert rec.n == 24841 and rec.dt == pytest.approx(1e-3, rel=1e-4) and rec.v is None
    from scipy.io import loadmat

    m = loadmat(EMPS_MAT)
    np.testing.assert_allclose(rec.u, m["gtau"][0, 0] * m["vir"].ravel())


@pytest.mark.parametrize(
    "mutate,needle",
    [
        (lambda r: r.__setitem__((10, 2), np.nan), "x is NaN or infinite at sample 10"),
        (lambda r: r.__setitem__((50, 0), r[48, 0]), "time is not increasing at sample 50"),
        (lambda r: r.__setitem__((slice(60, None), 0), r[60:, 0] + 0.5), "irregular sampling at sample 60"),
    ],
)
def test_bad_data_is_named(tmp_path, mutate, needle):
    rows = good_rows()
    mutate(rows)
    with pytest.raises(RecordingError, match=needle):
        load_recording(write_csv(tmp_path / "r.csv", ["t", "u", "x", "v"], rows))


def test_bad_files(tmp_path):
    with pytest.raises(RecordingError, match="has no column 'u' for u"):
        load_recording(write_csv(tmp_path / "a.csv", ["t", "force", "x"], good_rows()[:, :3]))
    with pytest.raises(RecordingError, match="at least 20 needed"):
        load_recording(write_csv(tmp_path / "b.csv", ["t", "u", "x"], good_rows(5)[:, :3]))
    (tmp_path / "c.csv").write_text("t,u,x\n0,1,2\n1,2\n")
    with pytest.raises(RecordingError, match="line 3: 2 fields"):
        load_recording(tmp_path / "c.csv")
    (tmp_path / "d.mat").write_bytes(b"not a mat file at all" * 10)
    with pytest.raises(RecordingError, match="cannot read"):
        load_recording(tmp_path / "d.mat")
    with pytest.raises(RecordingError, match="no such file"):
        load_recording(tmp_path / "missing.csv")
    with pytest.raises(RecordingError, match="unknown format"):
        load_recording(tmp_path / "e.xlsx")
    with pytest.raises(RecordingError, match="neither a number nor a variable"):
        load_recording(write_csv(tmp_path / "f.csv", ["t", "u", "x"], good_rows()[:, :3]), scale={"u": "gtau"})
    with pytest.raises(RecordingError, match="expected NAME=VALUE"):
        parse_mapping("u=vir,x", "--columns")


def test_a_byte_order_mark_is_not_part_of_the_first_column_name(tmp_path):
    """Issue 9.8: 'no column 't' (it has: ..., \\ufefft)' for a CSV saved by a spreadsheet."""
    from servo.io.recording import load_recording

    t = np.arange(200) * 1e-3
    body = "t,u,x\n" + "".join(f"{a:.17g},{np.sin(a):.17g},{np.cos(a):.17g}\n" for a in t)
    p = tmp_path / "bom.csv"
    p.write_bytes(b"\xef\xbb\xbf" + body.encode())
    rec = load_recording(p)
    np.testing.assert_array_equal(rec.t, t)


@pytest.mark.parametrize("role", ["t", "u", "x"])
def test_values_beyond_any_physical_magnitude_are_one_error_line(role, tmp_path):
    """Issue 9.6: values near 1e300 went through to the fits (warnings, exit 70)."""
    from servo.errors import RecordingError
    from servo.io.recording import load_recording

    t = np.arange(200) * 1e-3
    cols = {"t": t, "u": np.sin(t), "x": np.cos(t)}
    cols[role] = cols[role] * 1e300 if role != "t" else t * 1e300
    p = tmp_path / "big.npz"
    np.savez(p, **cols)
    with pytest.raises(RecordingError, match=rf"{role} = .* is beyond any physical value") as err:
        load_recording(p)
    assert "\n" not in str(err.value)
