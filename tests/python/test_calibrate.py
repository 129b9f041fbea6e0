"""carmba.calibrate from images, from an observations.csv and from arrays against `carmba
calibrate` (without its cross-checks) on the demo's simulated calibration images
(configs/scenes/thesis_calibration.yaml, scripts/demo.sh step 2)."""
import csv
import json

import numpy as np
import pytest

from conftest import assert_rel, read_json, run_cli, source

GRID = ["--pattern", "circles", "--rows", "5", "--cols", "5", "--spacing-mm", "20"]


@pytest.fixture(scope="module")
def cli(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("calib")
    sim = tmp / "sim"
    run_cli("simulate", "--scene", source("configs", "scenes", "thesis_calibration.yaml"),
            "--out", str(sim))
    out = tmp / "out"
    run_cli("calibrate", "--images", str(sim / "*.png"), *GRID, "--no-mrcal", "--no-opencv",
            "--no-plots", "--out", str(out))
    return sim, out


def without_images(j):
    """camera.json with the view labels dropped (arrays have no file names)."""
    j = dict(j)
    j["views"] = [{k: v for k, v in view.items() if k != "image"} for view in j["views"]]
    return j


def test_from_images_equals_the_command(carmba, cli):
    sim, out = cli
    c = carmba.calibrate(images=str(sim / "*.png"), pattern="circles", rows=5, cols=5,
                         spacing_mm=20)
    assert json.loads(c.camera_json()) == read_json(out / "camera.json")
    j = read_json(out / "camera.json")
    assert_rel(c.camera.intrinsics, [j["fx"], j["fy"], j["cx"], j["cy"], *j["distortion"]])
    assert_rel(c.covariance, j["covariance"]["matrix"], what="covariance")
    assert_rel(c.camera.covariance, j["covariance"]["matrix"], what="camera covariance")
    assert_rel(c.sigmas, [j["sigmas"][n] for n in carmba.INTRINSIC_NAMES], what="sigmas")
    assert c.rms_px == j["rms_px"] and c.num_points == j["num_points"]
    assert c.cam_from_plate.shape == (j["num_views"], 6)


def observation_array(path):
    with open(path) as f:
        lines = f.read().splitlines()
    size = next(l for l in lines if l.startswith("# image_size:")).split()[2:]
    rows = list(csv.DictReader(l for l in lines if not l.startswith("#")))
    n_views = max(int(r["view"]) for r in rows) + 1
    a = np.full((n_views, 25, 2), np.nan)
    for r in rows:
        a[int(r["view"]), int(r["point"])] = float(r["u_px"]), float(r["v_px"])
    return a, (int(size[0]), int(size[1]))


def test_from_observations_csv_and_arrays(carmba, cli, tmp_path):
    """The command on its own observations.csv, against carmba.calibrate on the same file and
    on the same pixels as an array (views, 25, 2) with NaN for points not seen."""
    _, out = cli
    obs = out / "observations.csv"
    out2 = tmp_path / "out"
    run_cli("calibrate", "--observations", str(obs), "--no-mrcal", "--no-opencv", "--no-plots",
            "--out", str(out2))
    expected = read_json(out2 / "camera.json")
    from_csv = carmba.calibrate(observations=str(obs))
    assert json.loads(from_csv.camera_json()) == expected
    a, size = observation_array(obs)
    assert np.isnan(a).any() or a.shape[0] > 0
    from_array = carmba.calibrate(observations=a, image_size=size)
    mine = json.loads(from_array.camera_json())
    assert without_images(mine) == without_images(expected)


def test_calibrate_errors(carmba, tmp_path):
    with pytest.raises(carmba.Error, match="give exactly one of observations"):
        carmba.calibrate()
    with pytest.raises(carmba.Error, match=r"expected an array \(views, rows\*cols = 25, 2\)"):
        carmba.calibrate(observations=np.zeros((3, 24, 2)), image_size=(408, 408))
    with pytest.raises(carmba.Error, match="image_size"):
        carmba.calibrate(observations=np.zeros((3, 25, 2)))
    with pytest.raises(carmba.Error, match="no_such"):
        carmba.calibrate(images=str(tmp_path / "no_such" / "*.png"))


def test_array_errors_name_the_element(carmba, cli):
    """Arrays are held to an observations.csv's plausible ranges: a pixel that is infinite,
    absurd or half NaN names its element, an absurd image size names image_size, before any
    solve (where they would fail as "not finite" or a degenerate initialisation)."""
    _, out = cli
    a, size = observation_array(out / "observations.csv")
    seen = np.argwhere(~np.isnan(a[:, :, 0]))[0]
    v, k = int(seen[0]), int(seen[1])
    for bad in ([np.inf, 10.0], [1e12, 10.0], [np.nan, 10.0]):
        b = a.copy()
        b[v, k] = bad
        with pytest.raises(carmba.Error, match=rf"observations\[{v}, {k}\]: expected a pixel "
                                               r"\(u, v\), each -?[0-9e+.]+ \.\. [0-9e+.]+ px"):
            carmba.calibrate(observations=b, image_size=size)
    for bad in ((10**9, 10**9), (0, 5), (640.5, 480), (640,)):
        with pytest.raises(carmba.Error, match=r"image_size: expected \(width, height\), each an "
                                               r"integer 1 \.\. 65535 px"):
            carmba.calibrate(observations=a, image_size=bad)
    with pytest.raises(carmba.Error, match="observations: no views"):
        carmba.calibrate(observations=a[:0], image_size=size)


def test_images_and_files_go_through_the_problems_plate_reader(carmba, cli):
    """Images and observations.csv are read by the problem's plate-view reader (LoadPlateViews),
    as `carmba calibrate` reads its flags: its errors name the argument, and spacing_mm replaces
    the file's pitch (the plate poses' translations scale with it, the intrinsics stay)."""
    sim, out = cli
    with pytest.raises(carmba.Error, match=r"images: the grid \(circles 4 x 9: pattern, rows, "
                                           r"cols\) was found in 0 of 20 images: check rows and "
                                           r"cols; first skipped: .*calib_001\.png"):
        carmba.calibrate(images=str(sim / "*.png"), rows=4, cols=9)
    at_20 = carmba.calibrate(observations=str(out / "observations.csv"))
    at_25 = carmba.calibrate(observations=str(out / "observations.csv"), spacing_mm=25)
    assert_rel(at_25.camera.intrinsics, at_20.camera.intrinsics, rel=1e-6, what="intrinsics")
    assert_rel(at_25.cam_from_plate[:, 3:], 1.25 * at_20.cam_from_plate[:, 3:], rel=1e-6,
               what="plate translations")
