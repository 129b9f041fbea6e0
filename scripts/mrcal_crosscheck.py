#!/usr/bin/python3
# carmba's mrcal cross-check (run with Debian's /usr/bin/python3, which has python3-mrcal).
#
#   /usr/bin/python3 scripts/mrcal_crosscheck.py IN.json OUT.json
#
# IN.json (written by `carmba calibrate`): image_size, grid {rows, cols, spacing_mm}, views
# [[ [point_id, u, v], ... ], ...], carmba {intrinsics[9], poses[[rx ry rz tx ty tz]...],
# sigma_px, distance_mm, free_basis (optional)}, others {name: intrinsics[9]} (e.g. OpenCV,
# truth).
# Solves the same observations with mrcal (LENSMODEL_OPENCV5, no board warp, no regularization,
# no outlier rejection), seeded by mrcal's own seed_stereographic (falling back to carmba's
# solution if that fails, reported), and writes OUT.json: mrcal's intrinsics, RMS (per
# coordinate, mrcal's rms_reproj_error__pixels), the 9x9 covariance of the intrinsics
# (sigma^2 (J^T J)^-1 unpacked, the same sigma as carmba), projection uncertainty at the image
# centre and corners at distance_mm (mrcal.projection_uncertainty, worst direction) for mrcal's
# solution and for carmba's solution, and projection differences (mrcal.projection_diff) between
# carmba and mrcal and the others: in the shared camera frame (no transform) and after mrcal's
# fitted rotation, with that fit's floor. (The comparison with a known truth, against carmba's
# sigmas, is carmba's own: calib/truth_check.h.)
# Like with like: mrcal's optimizer frees all 9 intrinsics (it cannot hold single parameters).
# When carmba held some (or tied fy to fx), IN.json's carmba.free_basis is the 9 x k matrix A of
# carmba's free intrinsics (intrinsics = x0 + A d, x0 carmba's solution): the same observations
# are then also solved with the same free parameters -- Gauss-Newton on mrcal's own residuals and
# Jacobian (mrcal.optimizer_callback), from mrcal's all-free solution projected onto that set --
# and OUT.json's `held` gives its intrinsics, RMS, covariance and projection difference.
import json
import os
import sys
import time

import numpy as np
import mrcal


def joint(inp):
    """The joint problem's cross-check (IN.json with mode 'joint', written by `carmba solve` for a
    joint problem): plate views as board observations by the camera at the reference, object views
    as observations of fixed points (the markers at their CT positions, object frame = reference)
    by one camera extrinsics per object view, ONE intrinsics (LENSMODEL_OPENCV5, all free). Pixel
    weights: 1 for the plate, sigma_plate / sigma_object for the markers (mrcal weights residuals
    by the observation's weight; carmba whitens by sigma: the same optimum). Seeded from carmba's
    INITIAL values; mrcal's optimum is compared with carmba's."""
    W, H = inp['image_size']
    rows, cols = inp['grid']['rows'], inp['grid']['cols']
    spacing = inp['grid']['spacing_mm']
    plate = inp['plate_views']
    nv = len(plate)
    obs = np.zeros((nv, rows, cols, 3))
    obs[..., 2] = -1.0
    for i, v in enumerate(plate):
        for pid, u, vv in v:
            obs[i, pid // cols, pid % cols] = (u, vv, 1.0)
    w = inp['weight_object']
    points = np.array(inp['points'], dtype=float)
    obs_p, idx_p = [], []
    for iext, v in enumerate(inp['object_views']):
        for ipoint, u, vv in v:
            obs_p.append((u, vv, w))
            idx_p.append((ipoint, 0, iext))
    init = inp['initial']
    inputs = dict(intrinsics=np.array([init['intrinsics']], dtype=float),
                  extrinsics_rt_fromref=np.array(init['object_poses'], dtype=float),
                  frames_rt_toref=np.array(init['plate_poses'], dtype=float),
                  points=points,
                  observations_board=obs, indices_frame_camintrinsics_camextrinsics=np.array(
                      [[i, 0, -1] for i in range(nv)], dtype=np.int32),
                  observations_point=np.array(obs_p, dtype=float),
                  indices_point_camintrinsics_camextrinsics=np.array(idx_p, dtype=np.int32),
                  Npoints_fixed=len(points),
                  lensmodel='LENSMODEL_OPENCV5', imagersizes=np.array([[W, H]], dtype=np.int32),
                  calobject_warp=None,
                  do_optimize_intrinsics_core=True, do_optimize_intrinsics_distortions=True,
                  do_optimize_extrinsics=True, do_optimize_frames=True,
                  do_optimize_calobject_warp=False, do_apply_regularization=False,
                  do_apply_outlier_rejection=False, calibration_object_spacing=spacing,
                  point_min_range=1.0, point_max_range=1.0e6, verbose=False)
    t0 = time.time()
    stats = mrcal.optimize(**inputs)
    t_solve = time.time() - t0
    # libdogleg stops on its own (relative) thresholds, which on this problem leave the small
    # distortion terms ~1e-5 (relative) short of the optimum; solving again from its solution (a
    # fresh trust region; mrcal.optimize updates the inputs in place) converges them. Counted and
    # reported, not hidden.
    passes = 1
    for _ in range(4):
        before = inputs['intrinsics'].copy()
        stats = mrcal.optimize(**inputs)
        passes += 1
        if np.max(np.abs(inputs['intrinsics'] - before) / np.maximum(np.abs(before), 1e-300)) < 1e-9:
            break
    c = inp['carmba']
    basis = c.get('free_basis')
    held_iterations = None
    if basis is not None:
        # carmba held (or tied) some intrinsics: the same free set on mrcal's residuals and
        # Jacobian, from mrcal's all-free solution (solve_held).
        held, inputs = solve_held(inputs, inputs['intrinsics'][0], c['intrinsics'], basis, 1.0)
        held_iterations = held['iterations']
    ours = dict(inputs)
    ours['intrinsics'] = np.array([c['intrinsics']], dtype=float)
    ours['extrinsics_rt_fromref'] = np.array(c['object_poses'], dtype=float)
    ours['frames_rt_toref'] = np.array(c['plate_poses'], dtype=float)
    x = mrcal.optimizer_callback(**ours, no_jacobian=True, no_factorization=True)[1]
    # mrcal seeded AT carmba's optimum: if carmba's point is mrcal's optimum too, mrcal stays there.
    at_carmba = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in ours.items()}
    if basis is None:
        mrcal.optimize(**at_carmba)
    else:
        at_carmba = solve_held(at_carmba, c['intrinsics'], c['intrinsics'], basis, 1.0)[1]
    n_meas = int(np.count_nonzero(obs[..., 2] > 0) + len(obs_p)) * 2
    rms_all_free = float(stats['rms_reproj_error__pixels'])
    rms_mrcal = float(np.sqrt(np.sum(mrcal.optimizer_callback(
        **inputs, no_jacobian=True, no_factorization=True)[1][:n_meas] ** 2) / n_meas))
    return {
        'mode': 'joint',
        'solve_seconds': t_solve,
        'optimize_passes': passes,
        'held_gauss_newton_iterations': held_iterations,
        'intrinsics_seeded_at_carmba': at_carmba['intrinsics'][0].tolist(),
        'intrinsics': inputs['intrinsics'][0].tolist(),
        # `rms_px` belongs to `intrinsics`: the held solve's when carmba held intrinsics, and
        # `rms_px_all_free` to mrcal's own optimum with all nine free.
        'rms_px': rms_mrcal if basis is not None else rms_all_free,
        'rms_px_all_free': rms_all_free,
        'rms_px_of_carmba_solution': float(np.sqrt(np.sum(x[:n_meas] ** 2) / n_meas)),
        'rms_px_of_mrcal_solution': rms_mrcal,
        'noutliers': int(stats['Noutliers']),
        'mrcal_version': getattr(mrcal, '__version__', '2.2'),
    }


def solve_held(inputs, start, x0, basis, sigma, max_iterations=50):
    """The problem of `inputs` with carmba's free intrinsics: intrinsics = x0 + A d (A = basis,
    9 x k); every other state variable mrcal optimizes (frames, extrinsics) free. Gauss-Newton on
    mrcal's residuals and Jacobian (unpacked state), from `start` (mrcal's all-free intrinsics)
    projected onto that set; a step that raises the cost is halved. Returns the intrinsics, the
    RMS over the measurements (as mrcal's rms_reproj_error__pixels), the 9 x 9 covariance
    A C_d A^T (sigma^2 (J^T J)^-1, the rest marginalised) and the iterations; and a copy of
    `inputs` holding that solution."""
    A = np.array(basis, dtype=float).reshape(9, -1)
    k = A.shape[1]
    x0 = np.array(x0, dtype=float)
    cur = {key: (v.copy() if isinstance(v, np.ndarray) else v) for key, v in inputs.items()}
    cur['do_optimize_intrinsics_core'] = True
    cur['do_optimize_intrinsics_distortions'] = True
    cur['intrinsics'] = (x0 + A @ np.linalg.lstsq(A, np.array(start, dtype=float) - x0,
                                                  rcond=None)[0])[None, :]
    i0 = mrcal.state_index_intrinsics(0, **cur)
    nmeas = mrcal.num_measurements(**cur)

    def evaluate(b_unpacked=None):
        if b_unpacked is not None:
            mrcal.ingest_packed_state(b_unpacked / scale, **cur)
        b, x_, J_, _ = mrcal.optimizer_callback(**cur, no_factorization=True)
        J_ = J_.toarray() / scale[None, :]
        Jr = np.hstack([J_[:, i0:i0 + 9] @ A, np.delete(J_, np.s_[i0:i0 + 9], axis=1)])
        return b * scale, x_[:nmeas], Jr[:nmeas]

    scale = np.ones(len(mrcal.optimizer_callback(**cur, no_jacobian=True,
                                                 no_factorization=True)[0]))
    mrcal.unpack_state(scale, **cur)
    b, x, Jr = evaluate()
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        # The columns scaled to unit norm (fx ~ 2000 px beside k3 ~ 1e-3): an accurate step in
        # the weakly determined directions too.
        col = np.linalg.norm(Jr, axis=0)
        col[col == 0] = 1
        step = np.linalg.lstsq(Jr / col, -x, rcond=None)[0] / col
        cost = x @ x
        # The Gauss-Newton decrement: the cost the step can still remove; below 1e-16 of the cost
        # the state is within ~1e-8 sigma per residual of the optimum (the joint converges
        # linearly there, ~20x per iteration, to a floor near 1e-18).
        decrement = np.sum((Jr @ step) ** 2)
        lowered = False
        for _ in range(30):
            db = np.insert(step[k:], i0, A @ step[:k])
            b_try, x_try, J_try = evaluate(b + db)
            if x_try @ x_try <= cost:
                lowered = True
                break
            step = step / 2
        # No step lowers the cost: at the minimum to rounding. (Taking the last halved step there
        # kept the decrement, itself at rounding level, above 1e-16 of the cost in some processes
        # -- mrcal's linear algebra rounds with the memory's alignment -- for all 50 iterations,
        # and left k2 1e-6 off the other processes'.)
        if not lowered:
            break
        b, x, Jr = b_try, x_try, J_try
        if decrement <= 1e-16 * max(cost, 1e-300):
            break
    Cd = np.linalg.inv(Jr.T @ Jr)[:k, :k] * sigma * sigma
    cov = A @ Cd @ A.T
    mrcal.ingest_packed_state(b / scale, **cur)
    return ({'intrinsics': b[i0:i0 + 9].tolist(), 'rms_px': float(np.sqrt(np.mean(x * x))),
             'covariance': cov.tolist(), 'sigma': np.sqrt(np.maximum(np.diag(cov), 0)).tolist(),
             'iterations': iterations}, cur)


def main():
    inp = json.load(open(sys.argv[1]))
    if inp.get('mode') == 'joint':
        json.dump(joint(inp), open(sys.argv[2], 'w'), indent=1)
        return
    W, H = inp['image_size']
    rows, cols = inp['grid']['rows'], inp['grid']['cols']
    spacing = inp['grid']['spacing_mm']
    sigma = inp['carmba']['sigma_px']
    distance = inp['carmba']['distance_mm']
    views = inp['views']
    nv = len(views)
    obs = np.zeros((nv, rows, cols, 3))
    obs[..., 2] = -1.0
    for i, v in enumerate(views):
        for pid, u, vv in v:
            obs[i, pid // cols, pid % cols] = (u, vv, 1.0)
    imagersizes = np.array([[W, H]], dtype=np.int32)
    indices = np.array([[i, 0, -1] for i in range(nv)], dtype=np.int32)
    lens = 'LENSMODEL_OPENCV5'
    t0 = time.time()
    seed = 'seed_stereographic'
    try:
        ifc = np.array([[i, 0] for i in range(nv)], dtype=np.int32)
        core, _, frames = mrcal.seed_stereographic(
            imagersizes=imagersizes, focal_estimate=inp['carmba']['intrinsics'][0],
            indices_frame_camera=ifc, observations=obs, object_spacing=spacing)
        intr = np.zeros((1, 9))
        intr[0, :4] = core[0, :4]
        stages = [(False, True), (True, True)]
    except Exception as e:  # noqa: BLE001 (report any seeding failure)
        seed = 'carmba solution (seed_stereographic failed: %s)' % str(e).splitlines()[0]
        intr = np.array([inp['carmba']['intrinsics']], dtype=float)
        frames = np.array(inp['carmba']['poses'], dtype=float)
        stages = [(True, True)]
    inputs = dict(intrinsics=intr, extrinsics_rt_fromref=np.zeros((0, 6)),
                  frames_rt_toref=np.array(frames, dtype=float), points=None,
                  observations_board=obs.copy(), indices_frame_camintrinsics_camextrinsics=indices,
                  observations_point=None, indices_point_camintrinsics_camextrinsics=None,
                  lensmodel=lens, imagersizes=imagersizes, calobject_warp=None,
                  do_optimize_intrinsics_core=True, do_optimize_intrinsics_distortions=False,
                  do_optimize_extrinsics=True, do_optimize_frames=True,
                  do_optimize_calobject_warp=False, do_apply_regularization=False,
                  do_apply_outlier_rejection=False, calibration_object_spacing=spacing,
                  verbose=False)
    stats = None
    for core_only_first, _ in stages:
        inputs['do_optimize_intrinsics_distortions'] = core_only_first
        stats = mrcal.optimize(**inputs)
    seed_note = None
    x_ours = None
    if seed == 'seed_stereographic':
        # If mrcal's own seed led to a worse local minimum than carmba's solution, say so and
        # re-solve from carmba's solution (the comparison is then of the optimum, not the seeding).
        chk = dict(inputs)
        chk['intrinsics'] = np.array([inp['carmba']['intrinsics']], dtype=float)
        chk['frames_rt_toref'] = np.array(inp['carmba']['poses'], dtype=float)
        chk['do_optimize_intrinsics_distortions'] = True
        x_ours = mrcal.optimizer_callback(**chk, no_jacobian=True, no_factorization=True)[1]
        rms_ours = float(np.sqrt(np.mean(x_ours * x_ours)))
        if stats['rms_reproj_error__pixels'] > 1.01 * rms_ours:
            seed_note = ('mrcal from its own seed reached RMS %.6g px (carmba: %.6g px), a worse '
                         'local minimum; re-solved from carmba\'s solution' %
                         (stats['rms_reproj_error__pixels'], rms_ours))
            inputs = chk
            stats = mrcal.optimize(**inputs)
            seed = "carmba's solution (after mrcal's own seed failed)"
    t_solve = time.time() - t0
    model_mrcal = mrcal.cameramodel(optimization_inputs=inputs, icam_intrinsics=0)

    def covariance(inputs_):
        _, _, J, _ = mrcal.optimizer_callback(**inputs_, no_factorization=True)
        J = J.toarray()
        scale = np.ones(J.shape[1])
        mrcal.unpack_state(scale, **inputs_)
        C = np.linalg.inv(J.T @ J) * sigma * sigma
        C = C * scale[:, None] * scale[None, :]
        i0 = mrcal.state_index_intrinsics(0, **inputs_)
        return C[i0:i0 + 9, i0:i0 + 9]

    cov = covariance(inputs)

    # carmba's solution inside mrcal's machinery (for mrcal's uncertainty formula at our solution).
    ours = dict(inputs)
    ours['intrinsics'] = np.array([inp['carmba']['intrinsics']], dtype=float)
    ours['frames_rt_toref'] = np.array(inp['carmba']['poses'], dtype=float)
    ours['do_optimize_intrinsics_distortions'] = True
    model_ours = mrcal.cameramodel(optimization_inputs=ours, icam_intrinsics=0)
    # carmba's solution with mrcal's optimization_inputs, beside OUT.json: mrcal's uncertainty
    # tools (mrcal-show-projection-uncertainty, mrcal.projection_uncertainty) read it.
    model_ours.write(os.path.join(os.path.dirname(os.path.abspath(sys.argv[2])),
                                  'camera_with_optimization_inputs.cameramodel'))

    pixels = [('centre', ((W - 1) / 2, (H - 1) / 2)), ('top-left', (0, 0)),
              ('top-right', (W - 1, 0)), ('bottom-left', (0, H - 1)),
              ('bottom-right', (W - 1, H - 1))]

    def uncertainty(model):
        out = []
        for name, q in pixels:
            p = mrcal.unproject(np.array(q, dtype=float), *model.intrinsics(), normalize=True)
            s = mrcal.projection_uncertainty(p * distance, model=model, atinfinity=False,
                                             what='worstdirection-stdev',
                                             observed_pixel_uncertainty=sigma)
            s = float(s)
            out.append({'where': name, 'worst_px': s if np.isfinite(s) else None})
        return out

    def diff(intrinsics):
        # Both models come from the same observations (or, for the truth, the same detector), so
        # they share the camera frame: the primary figure compares them with no transform
        # (implied_Rt10 = identity). mrcal's own fitted rotation (projection_diff at infinity) is
        # reported beside it with its floor, the difference it finds between carmba's model and
        # itself: in a narrow field of view that fit is uncertain at about 0.01 px.
        m = mrcal.cameramodel(intrinsics=(lens, np.array(intrinsics, dtype=float)),
                              imagersize=(W, H))

        def stats(models, **kw):
            d, _, _, _ = mrcal.projection_diff(models, gridn_width=40, use_uncertainties=False,
                                               **kw)
            d = d[np.isfinite(d)]
            return float(np.sqrt(np.mean(d * d))), float(np.max(d))
        rms, mx = stats((model_ours, m), implied_Rt10=mrcal.identity_Rt())
        frms, fmx = stats((model_ours, m))
        floor, _ = stats((model_ours, model_ours))
        return {'rms_px': rms, 'max_px': mx, 'fitted_rms_px': frms, 'fitted_max_px': fmx,
                'fit_floor_rms_px': floor}

    held = None
    if inp['carmba'].get('free_basis') is not None:
        held = solve_held(inputs, model_mrcal.intrinsics()[1], inp['carmba']['intrinsics'],
                          inp['carmba']['free_basis'], sigma)[0]
        held['projection_diff'] = diff(held['intrinsics'])
    x = mrcal.optimizer_callback(**ours, no_jacobian=True, no_factorization=True)[1]
    # mrcal seeded AT carmba's optimum: if carmba's point is mrcal's optimum too, mrcal stays there.
    at_carmba = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in ours.items()}
    mrcal.optimize(**at_carmba)
    diffs = {'mrcal': diff(model_mrcal.intrinsics()[1])}
    for name, intrinsics in inp.get('others', {}).items():
        diffs[name] = diff(intrinsics)
    out = {
        'seed': seed,
        'seed_note': seed_note,
        'solve_seconds': t_solve,
        'intrinsics': model_mrcal.intrinsics()[1].tolist(),
        'rms_px': float(stats['rms_reproj_error__pixels']),
        'rms_px_of_carmba_solution': float(np.sqrt(np.mean(x * x))),
        'noutliers': int(stats['Noutliers']),
        'covariance': cov.tolist(),
        'sigma': np.sqrt(np.diag(cov)).tolist(),
        'projection_uncertainty_mrcal': uncertainty(model_mrcal),
        'projection_uncertainty_carmba_solution': uncertainty(model_ours),
        'projection_diff': diffs,
        'mrcal_version': getattr(mrcal, '__version__', '2.2'),
        'held': held,
    }
    json.dump(out, open(sys.argv[2], 'w'), indent=1)


if __name__ == '__main__':
    try:
        main()
    except Exception as e:  # noqa: BLE001 (one line on stderr, non-zero exit)
        print('mrcal_crosscheck: %s: %s' % (type(e).__name__, str(e).splitlines()[0] if str(e) else ''),
              file=sys.stderr)
        sys.exit(1)
