#!/usr/bin/python3
"""Camera tracking side by side: track_camera (one or more named configurations) and Open3D's
tensor dense SLAM loop on the same sequences, with ATE, time per frame and per-frame error plots.

  /usr/bin/python3 bench/peers.py run --track-camera build/examples/track_camera
  /usr/bin/python3 bench/peers.py run --track-camera build/examples/track_camera --quick
  /usr/bin/python3 bench/peers.py run --track-camera build/examples/track_camera \\
      --tc baseline= --tc pyramid="--pyramid 3" --sequences redkitchen_300,drop2
  /usr/bin/python3 bench/peers.py selftest

Sequences (--sequences, comma-separated; default all of them):
  redkitchen_300   ../shared/data/redkitchen_300 itself (300 frames of a real Kinect recording)
  drop2, drop3     redkitchen_300 with every 2nd / 3rd frame kept (there_and_back.py --frames 300 --step K)
  tab600, tab900   redkitchen_300 there and back (forward, backward, forward) for 600 / 900 frames
  tab900s2         tab900 with every 2nd frame kept (450 frames)
  synthetic-long   the built-in scene synthetic:long (900 frames, static room, Kinect noise, fast
                   segments), exported by export_synthetic (next to track_camera) as a TUM folder
redkitchen_300 and tab600 are the first 300 and 600 frames of tab900 (the same depth images in the
same order; only the timestamps differ): both trackers are causal, so when tab900 is in the run
their rows are its first poses (re-stamped and evaluated against their own ground truth), marked
so in the table, with tab900's time per frame; --no-prefix runs them on their own. The script
checks that the depth files agree before it reads a run this way.
The real ones are made under <out>/seq/ by bench/there_and_back.py (links into ../shared/data, no
copy; EMFUSION_SHARED_DIR=DIR reads DIR/data instead of ../shared/data); when redkitchen_300 is
absent they are skipped with a message. --quick runs
the first 60 frames of redkitchen_300 and synthetic-long.

Methods. track_camera runs once per --tc NAME=ARGS (default: one configuration, 'track_camera',
with --tc-args, default none; its own defaults: a sparse volume of 1 cm voxels, three pyramid levels,
every 2nd pixel of a 640x480 frame; --tc paper="--volume dense --pyramid 1 --stride 1 --reference-solver"
is the paper's tracker): `track_camera SEQ TRAJ ARGS`.
Its time per frame is the process's wall time over the frames (reading PNGs included, as for Open3D),
and its CPU time (user + system, all threads; from getrusage of the child), which a machine shared
with other work inflates less than the wall time.

'open3d' is Open3D's tensor dense SLAM model (t.pipelines.slam.Model) assembled from its parts,
because Debian's python3-open3d 0.16 is built without IPP: on the CPU Model.track_frame_to_model
and rgbd_odometry_multi_scale stop with "not implemented" (both bilateral-filter the depth, and
Image.filter_bilateral, pyrdown and PyrDownDepth need IPP there). What runs, per frame, with the
pose T (camera to world, the first camera's frame is the world):
  1. ray cast the model: VoxelBlockGrid.ray_cast at T over the blocks the previous frame touched
     (as Model.synthesize_model_frame does), depth rendered; weight threshold min(frame, 3);
  2. track: multi-scale point-to-plane ICP of the new depth against the ray cast depth, as in
     RGBDOdometryMultiScale's PointToPlane path: 3 levels, coarse to fine with 6, 3, 1 iterations
     (track_frame_to_model's defaults), each iteration one
     t.pipelines.odometry.compute_odometry_result_point_to_plane (projective association, outlier
     truncation 0.07 m, Huber 0.05 m: OdometryLossParams' defaults), stopping a level early when
     the relative change of fitness and inlier RMSE is below 1e-6 (OdometryConvergenceCriteria).
     Vertex maps come from Image.create_vertex_map, target normals from Image.create_normal_map of
     the ray cast depth's vertex map; the pyramid levels are made here (numpy): a 2x2 block's mean
     of its valid depths when they lie within 2 x 0.07 m of each other, else invalid; intrinsics
     halved per level. Not reproduced: the bilateral filter on the target depth before its normals
     (the ray cast depth is smooth already).
  3. keep the step: Open3D's dense_slam example drops a frame's update whose translation is over
     its odometry_distance_thr, which on fast motion freezes the pose; --o3d-reject M does the
     same (0, the default, keeps every step);
  4. integrate the frame at the new pose: VoxelBlockGrid (tsdf, weight) with 1 cm voxels, blocks of
     16^3, depth_max 3 m, truncation 8 voxels (Open3D's default multiplier; --o3d-trunc to change).
Timing: the loop's wall and CPU time per frame, image reading included, import and set-up not.

ATE: the RMSE of translation after the best rigid alignment (Horn's closed form, no scale) of the
estimate to the ground truth, poses matched by timestamp within 0.02 s (shared FORMATS.md section
6). The table's ATE comes from the repo's evaluate_trajectory (next to track_camera, or
--evaluate); the script's own Horn alignment gives the per-frame errors of the plots, and its RMSE
is checked against evaluate_trajectory's (a difference over 0.1 mm is reported).

Writes into --out (default bench/out/peers, bench/out/peers-quick for --quick):
  table.md                   the table (also printed): ATE (cm) and ms/frame (wall / CPU) per method and sequence
  results.json               every number, command and time
  plots/<sequence>.svg       per-frame translation error (after alignment) of every method
  traj/<sequence>/<method>.txt, logs/<sequence>-<method>.log

`selftest` checks the script's own parts (Horn alignment of a known motion, the depth pyramid, the
SVG writer, argument errors) in a second, without Open3D or data. Python 3 with numpy; Open3D from
Debian's python3-open3d (apt-get install python3-open3d); without it, --methods without open3d.
"""

import argparse
import json
import math
import os
import resource
import shlex
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
# EMFUSION_SHARED_DIR: a copy of the shared folder elsewhere (as bench/generalisation.py).
SHARED_DATA = os.path.join(os.environ.get('EMFUSION_SHARED_DIR') or os.path.normpath(os.path.join(REPO, '..', 'shared')),
                           'data')
KITCHEN = os.path.join(SHARED_DATA, 'redkitchen_300')

# name: (kind, arguments). Real ones: there_and_back.py --frames --step (None: the base itself).
SEQUENCES = {
    'redkitchen_300': ('real', None),
    'drop2': ('real', (300, 2)),
    'drop3': ('real', (300, 3)),
    'tab600': ('real', (600, 1)),
    'tab900': ('real', (900, 1)),
    'synthetic-long': ('synthetic', 'synthetic:long'),
    'tab900s2': ('real', (900, 2)),
}
# Sequences whose frames are the first ones of another (same depth images in the same order): the
# trackers are causal, so their results are the longer run's first poses. Run once, read twice.
PREFIX_OF = {'redkitchen_300': 'tab900', 'tab600': 'tab900'}
QUICK = ['redkitchen_300', 'synthetic-long']
QUICK_FRAMES = 60
MATCH_SECONDS = 0.02


class UsageError(Exception):
    pass


# ---------------------------------------------------------------- reading and alignment

def read_rows(path):
    rows = []
    with open(path) as f:
        for line in f:
            line = line.split('#', 1)[0].strip()
            if line:
                rows.append(line.replace(',', ' ').split())
    return rows


def read_trajectory(path):
    """[(t, (x, y, z))] of a TUM trajectory; ValueError naming the file and line for a bad one."""
    out = []
    for i, r in enumerate(read_rows(path)):
        if len(r) != 8:
            raise ValueError('%s: pose %d has %d fields, expected 8 (timestamp tx ty tz qx qy qz qw)'
                             % (path, i + 1, len(r)))
        try:
            v = [float(x) for x in r[:4]]
        except ValueError:
            raise ValueError('%s: pose %d: %r is not a number' % (path, i + 1, ' '.join(r[:4])))
        out.append((v[0], tuple(v[1:4])))
    return out


def match(est, gt, max_dt=MATCH_SECONDS):
    """Pairs (t, p_est, p_gt): each estimated pose with the ground-truth pose nearest in time."""
    import bisect
    gts = [t for t, _ in gt]
    pairs = []
    for t, p in est:
        k = bisect.bisect_left(gts, t)
        best = None
        for j in (k - 1, k):
            if 0 <= j < len(gts) and (best is None or abs(gts[j] - t) < abs(gts[best] - t)):
                best = j
        if best is not None and abs(gts[best] - t) <= max_dt:
            pairs.append((t, p, gt[best][1]))
    return pairs


def horn(est, gt):
    """Rotation R and translation c of the best rigid fit R est + c ~ gt (least squares, no scale):
    Horn's closed form through the SVD of the cross-covariance (Umeyama without scale)."""
    import numpy as np
    a = np.asarray(est, dtype=float)
    b = np.asarray(gt, dtype=float)
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((b - mb).T @ (a - ma))
    d = np.eye(3)
    d[2, 2] = 1.0 if np.linalg.det(u @ vt) > 0 else -1.0
    r = u @ d @ vt
    return r, mb - r @ ma


def aligned_errors(est_path, gt_path):
    """(timestamps, per-pose translation errors in m) after the rigid alignment."""
    import numpy as np
    pairs = match(read_trajectory(est_path), read_trajectory(gt_path))
    if len(pairs) < 3:
        raise ValueError('only %d poses of %s match %s within %.2f s' % (len(pairs), est_path, gt_path, MATCH_SECONDS))
    t = [p[0] for p in pairs]
    e = np.array([p[1] for p in pairs])
    g = np.array([p[2] for p in pairs])
    r, c = horn(e, g)
    err = np.linalg.norm((e @ r.T + c) - g, axis=1)
    return t, [float(x) for x in err]


# ---------------------------------------------------------------- SVG plots

def svg_plot(path, title, series, xlabel='frame', ylabel='translation error (cm)'):
    """A line plot of {name: [(x, y)]} as a self-contained SVG file."""
    colours = ['#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2', '#17becf']
    w, h, left, right, top, bottom = 900, 360, 60, 180, 30, 40
    xs = [x for s in series.values() for x, _ in s]
    ys = [y for s in series.values() for _, y in s if math.isfinite(y)]
    x0, x1 = (min(xs), max(xs)) if xs else (0, 1)
    y1 = max(ys) if ys else 1.0
    x1 = x1 if x1 > x0 else x0 + 1
    y1 = nice_ceiling(y1 if y1 > 0 else 1.0)

    def px(x):
        return left + (x - x0) / (x1 - x0) * (w - left - right)

    def py(y):
        return top + (1 - min(y, y1) / y1) * (h - top - bottom)

    out = ['<svg xmlns="http://www.w3.org/2000/svg" width="%d" height="%d" viewBox="0 0 %d %d" '
           'font-family="sans-serif" font-size="12">' % (w, h, w, h),
           '<rect width="100%" height="100%" fill="white"/>',
           '<text x="%d" y="18" font-size="14">%s</text>' % (left, escape(title))]
    for k in range(5):
        y = y1 * k / 4
        out.append('<line x1="%d" x2="%d" y1="%.1f" y2="%.1f" stroke="#ddd"/>' % (left, w - right, py(y), py(y)))
        out.append('<text x="%d" y="%.1f" text-anchor="end">%g</text>' % (left - 5, py(y) + 4, round(y, 3)))
    for k in range(6):
        x = x0 + (x1 - x0) * k / 5
        out.append('<text x="%.1f" y="%d" text-anchor="middle">%d</text>' % (px(x), h - bottom + 15, round(x)))
    out.append('<rect x="%d" y="%d" width="%d" height="%d" fill="none" stroke="black"/>'
               % (left, top, w - left - right, h - top - bottom))
    out.append('<text x="%d" y="%d" text-anchor="middle">%s</text>' % ((left + w - right) // 2, h - 5, escape(xlabel)))
    out.append('<text x="14" y="%d" transform="rotate(-90 14 %d)" text-anchor="middle">%s</text>'
               % ((top + h - bottom) // 2, (top + h - bottom) // 2, escape(ylabel)))
    for i, (name, pts) in enumerate(series.items()):
        colour = colours[i % len(colours)]
        if pts:
            d = ' '.join('%s%.1f,%.1f' % ('M' if j == 0 else 'L', px(x), py(y)) for j, (x, y) in enumerate(pts))
            out.append('<path d="%s" fill="none" stroke="%s" stroke-width="1.3"/>' % (d, colour))
        ly = top + 16 * i + 10
        out.append('<line x1="%d" x2="%d" y1="%d" y2="%d" stroke="%s" stroke-width="3"/>'
                   % (w - right + 10, w - right + 30, ly, ly, colour))
        out.append('<text x="%d" y="%d">%s</text>' % (w - right + 35, ly + 4, escape(name)))
    out.append('</svg>')
    with open(path, 'w') as f:
        f.write('\n'.join(out) + '\n')


def nice_ceiling(v):
    e = 10 ** math.floor(math.log10(v))
    for m in (1, 2, 2.5, 5, 10):
        if v <= m * e + 1e-12:
            return m * e
    return 10 * e


def escape(s):
    return str(s).replace('&', '&amp;').replace('<', '&lt;').replace('>', '&gt;')


# ---------------------------------------------------------------- sequences

def depth_list(seq):
    """[(timestamp, depth path)] of a TUM-layout folder: associations.txt, else depth.txt."""
    assoc = os.path.join(seq, 'associations.txt')
    if os.path.isfile(assoc):
        rows = read_rows(assoc)
        return [(float(r[2]), os.path.join(seq, r[3])) for r in rows]
    rows = read_rows(os.path.join(seq, 'depth.txt'))
    return [(float(r[0]), os.path.join(seq, r[1])) for r in rows]


def intrinsics_of(seq):
    """fx fy cx cy width height from calibration.txt, else the TUM default (525, 319.5, 239.5, 640x480)."""
    path = os.path.join(seq, 'calibration.txt')
    if not os.path.isfile(path):
        return 525.0, 525.0, 319.5, 239.5, 640, 480
    r = read_rows(path)[0]
    return float(r[0]), float(r[1]), float(r[2]), float(r[3]), int(float(r[4])), int(float(r[5]))


def prepare_sequence(name, args, log):
    """The folder of sequence `name`, made if needed; None (with a message) when it cannot be."""
    kind, spec = SEQUENCES[name]
    if kind == 'real':
        if not os.path.isfile(os.path.join(KITCHEN, 'associations.txt')):
            log('skipping %s: %s is absent (the real sequences need ../shared/data)' % (name, KITCHEN))
            return None
        if spec is None:
            return KITCHEN
        frames, step = spec
        out = os.path.join(args.out, 'seq', name)
        cmd = ['/usr/bin/python3', os.path.join(HERE, 'there_and_back.py'), '--base', KITCHEN, '--frames', str(frames),
               '--step', str(step), '--out', out]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        return out
    exporter = args.export_synthetic
    if not os.path.isfile(exporter) or not os.access(exporter, os.X_OK):
        log('skipping %s: no export_synthetic binary at %s (build the target, or pass --export-synthetic)'
            % (name, exporter))
        return None
    frames = QUICK_FRAMES if args.quick else 0
    out = os.path.join(args.out, 'seq', name)
    stamp = os.path.join(out, 'export.txt')
    want = '%s %d\n' % (spec, frames)
    if not (os.path.isfile(stamp) and open(stamp).read() == want):
        cmd = [exporter, spec, out] + (['--max-frames', str(frames)] if frames else [])
        log('exporting %s: %s' % (spec, ' '.join(cmd)))
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        with open(stamp, 'w') as f:
            f.write(want)
    return out


# ---------------------------------------------------------------- Open3D

def pyramid_down(depth, depth_diff):
    """Half-size depth (metres, NaN invalid): each 2x2 block's mean of its valid depths when they lie
    within 2 * depth_diff of each other, else NaN."""
    import warnings
    import numpy as np
    h, w = depth.shape[0] // 2 * 2, depth.shape[1] // 2 * 2
    b = depth[:h, :w].reshape(h // 2, 2, w // 2, 2).transpose(0, 2, 1, 3).reshape(h // 2, w // 2, 4)
    with warnings.catch_warnings():   # all-NaN blocks are expected: they stay NaN
        warnings.simplefilter('ignore', RuntimeWarning)
        lo, hi = np.nanmin(b, axis=2), np.nanmax(b, axis=2)
        mean = np.nanmean(b, axis=2)
    mean[~(hi - lo <= 2 * depth_diff)] = np.nan
    return mean.astype(np.float32)


def run_open3d(seq, traj_out, max_frames, trunc_multiplier, reject, log):
    """Open3D's dense SLAM loop as assembled in the docstring; returns (frames, seconds)."""
    import numpy as np
    import open3d as o3d
    o3c = o3d.core
    od = o3d.t.pipelines.odometry
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    dev = o3c.Device('CPU:0')
    frames = depth_list(seq)
    if max_frames:
        frames = frames[:max_frames]
    fx, fy, cx, cy, width, height = intrinsics_of(seq)
    scale, depth_max, depth_min, depth_diff, huber = 5000.0, 3.0, 0.1, 0.07, 0.05
    levels, iterations = 3, [6, 3, 1]   # coarse to fine
    nan = float('nan')

    def k_of(level):
        s = 0.5 ** level
        return o3c.Tensor([[fx * s, 0, cx * s], [0, fy * s, cy * s], [0, 0, 1]], dtype=o3c.float64)

    ks = [k_of(level) for level in range(levels)]

    def vertex_maps(depth_m):
        out, d = [], depth_m
        for level in range(levels):
            if level:
                d = pyramid_down(d, depth_diff)
            img = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(d[:, :, None])))
            out.append(img.create_vertex_map(ks[level], nan))
        return out

    vbg = o3d.t.geometry.VoxelBlockGrid(attr_names=('tsdf', 'weight'), attr_dtypes=(o3c.float32, o3c.float32),
                                        attr_channels=((1), (1)), voxel_size=0.01, block_resolution=16,
                                        block_count=40000, device=dev)
    pose = np.eye(4)
    poses, blocks = [], None
    t_start, cpu_start = time.time(), time.process_time()
    for i, (stamp, path) in enumerate(frames):
        raw = o3d.t.io.read_image(path)
        if raw.is_empty():
            raise RuntimeError('cannot read depth image %s' % path)
        if i > 0:
            extrinsic = o3c.Tensor(np.linalg.inv(pose))
            rc = vbg.ray_cast(block_coords=blocks, intrinsic=ks[0], extrinsic=extrinsic, width=width, height=height,
                              render_attributes=['depth'], depth_scale=scale, depth_min=depth_min, depth_max=depth_max,
                              weight_threshold=min(float(i), 3.0), trunc_voxel_multiplier=trunc_multiplier)
            target = rc['depth'].numpy()[:, :, 0] / scale
            target[~(target > 0)] = nan
            source = raw.as_tensor().numpy()[:, :, 0].astype(np.float32) / scale
            source[~((source > 0) & (source <= depth_max))] = nan
            src_v = vertex_maps(source)
            tgt_v = vertex_maps(target)
            tgt_n = [v.create_normal_map(nan) for v in tgt_v]
            delta = o3c.Tensor(np.eye(4))
            for level in reversed(range(levels)):
                prev = None
                for _ in range(iterations[levels - 1 - level]):
                    res = od.compute_odometry_result_point_to_plane(
                        src_v[level].as_tensor(), tgt_v[level].as_tensor(), tgt_n[level].as_tensor(), ks[level],
                        delta, depth_diff, huber)
                    # The result is the increment on top of the pose it started from, as
                    # RGBDOdometryMultiScale composes it: trans = delta * trans.
                    delta = res.transformation @ delta
                    if prev is not None and abs(res.fitness - prev[0]) <= 1e-6 * max(prev[0], 1e-12) and \
                            abs(res.inlier_rmse - prev[1]) <= 1e-6 * max(prev[1], 1e-12):
                        break
                    prev = (res.fitness, res.inlier_rmse)
            step = delta.numpy()
            if reject and np.linalg.norm(step[:3, 3]) > reject:
                log('  open3d: frame %d: step of %.3f m over --o3d-reject %.3f m dropped' %
                    (i, np.linalg.norm(step[:3, 3]), reject))
            else:
                pose = pose @ step
        extrinsic = o3c.Tensor(np.linalg.inv(pose))
        blocks = vbg.compute_unique_block_coordinates(raw, ks[0], extrinsic, scale, depth_max, trunc_multiplier)
        vbg.integrate(blocks, raw, ks[0], extrinsic, scale, depth_max, trunc_multiplier)
        poses.append((stamp, pose.copy()))
    seconds, cpu_seconds = time.time() - t_start, time.process_time() - cpu_start
    with open(traj_out, 'w') as f:
        f.write('# timestamp tx ty tz qx qy qz qw (Open3D dense SLAM loop, bench/peers.py)\n')
        for stamp, p in poses:
            q = quaternion(p[:3, :3])
            f.write('%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n' % ((stamp,) + tuple(p[:3, 3]) + q))
    return len(frames), seconds, cpu_seconds


def quaternion(r):
    """(qx, qy, qz, qw) of a rotation matrix, w >= 0."""
    tr = r[0][0] + r[1][1] + r[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = ((r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s, 0.25 * s)
    elif r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        s = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2
        q = (0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s, (r[2][1] - r[1][2]) / s)
    elif r[1][1] > r[2][2]:
        s = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2
        q = ((r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s, (r[0][2] - r[2][0]) / s)
    else:
        s = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2
        q = ((r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s, (r[1][0] - r[0][1]) / s)
    n = math.sqrt(sum(x * x for x in q))
    q = tuple(x / n for x in q)
    return q if q[3] >= 0 else tuple(-x for x in q)


# ---------------------------------------------------------------- running

def evaluate(binary, gt, est):
    """ATE RMSE (m) and the line evaluate_trajectory printed."""
    p = subprocess.run([binary, gt, est], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in p.stdout.splitlines():
        if line.startswith('ATE RMSE '):
            return float(line.split()[2]), line
    raise RuntimeError('%s %s %s: no ATE line in its output:\n%s' % (binary, gt, est, p.stdout))


def parse_configs(args):
    configs = []
    for item in args.tc or []:
        if '=' not in item:
            raise UsageError("--tc expects NAME=ARGS (e.g. --tc 'pyramid=--pyramid 3'), got %r" % item)
        name, rest = item.split('=', 1)
        if not name or not all(c.isalnum() or c in '-_.' for c in name):
            raise UsageError('--tc name %r: use letters, digits, - _ . only' % name)
        if name == 'open3d' or any(name == c[0] for c in configs):
            raise UsageError('--tc name %r is used twice (or is open3d)' % name)
        configs.append((name, shlex.split(rest)))
    if not configs:
        configs = [('track_camera', shlex.split(args.tc_args or ''))]
    elif args.tc_args:
        raise UsageError('--tc-args and --tc both given: put the flags into each --tc NAME=ARGS')
    return configs


def check_args(args):
    if args.sequences:
        names = [s for s in args.sequences.split(',') if s]
        unknown = [s for s in names if s not in SEQUENCES]
        if unknown:
            raise UsageError('unknown sequence %s (known: %s)' % (', '.join(repr(u) for u in unknown),
                                                                  ', '.join(SEQUENCES)))
    else:
        names = QUICK if args.quick else list(SEQUENCES)
    methods = [m for m in args.methods.split(',') if m]
    for m in methods:
        if m not in ('track_camera', 'open3d'):
            raise UsageError("--methods: unknown method %r (track_camera, open3d)" % m)
    if 'track_camera' in methods:
        if not args.track_camera:
            raise UsageError('--track-camera PATH is required when track_camera is among --methods')
        if not (os.path.isfile(args.track_camera) and os.access(args.track_camera, os.X_OK)):
            raise UsageError('--track-camera %s: not an executable file' % args.track_camera)
    evaluator = args.evaluate or (os.path.join(os.path.dirname(args.track_camera), 'evaluate_trajectory')
                                  if args.track_camera else '')
    if not (evaluator and os.path.isfile(evaluator) and os.access(evaluator, os.X_OK)):
        raise UsageError('no evaluate_trajectory binary at %r (pass --evaluate PATH)' % evaluator)
    args.evaluate = evaluator
    if not args.export_synthetic:
        args.export_synthetic = os.path.join(os.path.dirname(args.track_camera or evaluator), 'export_synthetic')
    if args.max_frames is not None and args.max_frames < 1:
        raise UsageError('--max-frames expects a positive integer, got %d' % args.max_frames)
    if 'open3d' in methods:
        try:
            import open3d  # noqa: F401
        except ImportError:
            raise UsageError('open3d is not importable by %s: apt-get install python3-open3d, or --methods '
                             'track_camera' % sys.executable)
    return names, methods


def run(args):
    names, methods = check_args(args)
    configs = parse_configs(args) if 'track_camera' in methods else []
    if args.quick and args.max_frames is None:
        args.max_frames = QUICK_FRAMES
    for d in ('seq', 'traj', 'logs', 'plots'):
        os.makedirs(os.path.join(args.out, d), exist_ok=True)

    def log(msg):
        print(msg, flush=True)

    method_names = [c[0] for c in configs] + (['open3d'] if 'open3d' in methods else [])
    results = {'command': ' '.join(shlex.quote(a) for a in sys.argv), 'started': time.strftime('%Y-%m-%d %H:%M:%S'),
               'cpu_count': os.cpu_count(), 'configs': {n: a for n, a in configs}, 'sequences': {}}
    previous, reuse = {}, [m for m in (args.reuse or '').split(',') if m]
    for m in reuse:
        if m not in method_names:
            raise UsageError('--reuse %s: not a method of this run (%s)' % (m, ', '.join(method_names)))
    if reuse and os.path.isfile(os.path.join(args.out, 'results.json')):
        with open(os.path.join(args.out, 'results.json')) as f:
            previous = json.load(f)
    env = dict(os.environ)
    env.setdefault('OMP_WAIT_POLICY', 'passive')
    if not args.no_prefix:   # a longer run first, so that its prefixes can be read from it
        names = sorted(names, key=lambda m: 0 if m in PREFIX_OF.values() else 1)
    for name in names:
        seq = prepare_sequence(name, args, log)
        if seq is None:
            results['sequences'][name] = {'skipped': True}
            continue
        gt = os.path.join(seq, 'groundtruth.txt')
        n_all = len(depth_list(seq))
        n = min(n_all, args.max_frames) if args.max_frames else n_all
        entry = {'path': seq, 'frames': n, 'methods': {}}
        results['sequences'][name] = entry
        os.makedirs(os.path.join(args.out, 'traj', name), exist_ok=True)
        parent = PREFIX_OF.get(name) if not args.no_prefix else None
        parent_entry = results['sequences'].get(parent) if parent else None
        if parent_entry and not is_prefix(seq, parent_entry.get('path'), n):
            parent_entry = None
        for method in method_names:
            traj = os.path.join(args.out, 'traj', name, method + '.txt')
            logfile = os.path.join(args.out, 'logs', '%s-%s.log' % (name, method))
            parent_rec = parent_entry['methods'].get(method, {}) if parent_entry else {}
            if 'ms_per_frame' in parent_rec and parent_entry['frames'] >= n:
                log('%s: %s: the first %d poses of its %s run' % (name, method, n, parent))
                rec = {'from': parent, 'ms_per_frame': parent_rec['ms_per_frame'],
                       'cpu_ms_per_frame': parent_rec['cpu_ms_per_frame']}
                try:
                    first_poses(os.path.join(args.out, 'traj', parent, method + '.txt'), seq, n, traj)
                    score(rec, args.evaluate, gt, traj, log)
                except (OSError, RuntimeError, ValueError) as e:
                    rec = {'error': str(e)}
                    log('  failed: %s' % e)
                entry['methods'][method] = rec
                continue
            if method == 'open3d':
                cmd = ['/usr/bin/python3', os.path.abspath(__file__), 'open3d', seq, traj, '--max-frames', str(n),
                       '--o3d-trunc', str(args.o3d_trunc), '--o3d-reject', str(args.o3d_reject)]
            else:
                cmd = [args.track_camera, seq, traj, '--max-frames', str(n)] + dict(configs)[method]
            old = previous.get('sequences', {}).get(name, {}).get('methods', {}).get(method, {})
            if method in reuse and 'ms_per_frame' in old and old.get('command') == ' '.join(shlex.quote(c) for c in cmd) \
                    and os.path.isfile(traj):
                log('%s: %s: reusing the run in %s (--reuse)' % (name, method, traj))
                rec = {k: old[k] for k in ('command', 'wall_s', 'returncode', 'ms_per_frame', 'cpu_ms_per_frame')}
                rec['reused'] = True
                try:
                    score(rec, args.evaluate, gt, traj, log)
                except (OSError, RuntimeError, ValueError) as e:
                    rec = {'error': str(e)}
                    log('  failed: %s' % e)
                entry['methods'][method] = rec
                continue
            log('%s: %s (%d frames) ...' % (name, method, n))
            t0, r0 = time.time(), resource.getrusage(resource.RUSAGE_CHILDREN)
            try:
                with open(logfile, 'w') as lf:
                    p = subprocess.run(cmd, stdout=lf, stderr=subprocess.STDOUT, env=env)
                wall = time.time() - t0
                r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
                cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
                rec = {'command': ' '.join(shlex.quote(c) for c in cmd), 'wall_s': wall, 'returncode': p.returncode}
                if p.returncode != 0:
                    rec['error'] = 'exit %d (see %s)' % (p.returncode, logfile)
                    log('  failed: %s' % rec['error'])
                else:
                    loop = wall
                    if method == 'open3d':   # the loop alone: not the import and set-up
                        for line in open(logfile):
                            if line.startswith('open3d loop seconds '):
                                loop, cpu = float(line.split()[3]), float(line.split()[5])
                    rec['ms_per_frame'] = 1000 * loop / n
                    rec['cpu_ms_per_frame'] = 1000 * cpu / n
                    score(rec, args.evaluate, gt, traj, log)
            except (OSError, RuntimeError, ValueError, subprocess.CalledProcessError) as e:
                rec = {'error': str(e)}
                log('  failed: %s' % e)
            entry['methods'][method] = rec
        series = {m: [(i, 100 * e) for i, e in enumerate(r['errors'])]
                  for m, r in entry['methods'].items() if 'errors' in r}
        if series:
            svg_plot(os.path.join(args.out, 'plots', name + '.svg'),
                     '%s: translation error after rigid alignment, per frame' % name, series)
        with open(os.path.join(args.out, 'results.json'), 'w') as f:
            json.dump(results, f, indent=1)
    table = make_table(results, method_names)
    print(table)
    with open(os.path.join(args.out, 'table.md'), 'w') as f:
        f.write(table)
    with open(os.path.join(args.out, 'results.json'), 'w') as f:
        json.dump(results, f, indent=1)
    print('wrote %s (table.md, results.json, plots/)' % args.out)
    return 0


def score(rec, evaluator, gt, traj, log):
    """ATE of a trajectory into rec: evaluate_trajectory's, and the script's per-frame errors."""
    rec['ate_m'], rec['evaluate'] = evaluate(evaluator, gt, traj)
    _, errs = aligned_errors(traj, gt)
    rec['ate_script_m'] = math.sqrt(sum(e * e for e in errs) / len(errs))
    rec['max_error_m'] = max(errs)
    rec['errors'] = errs
    if abs(rec['ate_script_m'] - rec['ate_m']) > 1e-4:
        log('  note: the script\'s Horn ATE %.4f m differs from evaluate_trajectory\'s %.4f m'
            % (rec['ate_script_m'], rec['ate_m']))
    log('  ATE %.2f cm (max %.2f cm), %.0f ms/frame wall, %.0f ms/frame CPU' %
        (100 * rec['ate_m'], 100 * rec['max_error_m'], rec['ms_per_frame'], rec['cpu_ms_per_frame']))


def is_prefix(seq, parent, n):
    """True when the first n depth images of seq are the first n of parent (same files, same order)."""
    if not parent or not os.path.isdir(parent):
        return False
    a, b = depth_list(seq), depth_list(parent)
    return len(a) >= n and len(b) >= n and all(
        os.path.realpath(x[1]) == os.path.realpath(y[1]) for x, y in zip(a[:n], b[:n]))


def first_poses(parent_traj, seq, n, out):
    """The first n poses of parent_traj, stamped with seq's first n depth timestamps, into out."""
    rows = [r for r in read_rows(parent_traj)]
    if len(rows) < n:
        raise ValueError('%s has %d poses, fewer than the %d needed' % (parent_traj, len(rows), n))
    stamps = [t for t, _ in depth_list(seq)[:n]]
    with open(out, 'w') as f:
        f.write('# timestamp tx ty tz qx qy qz qw: the first %d poses of %s, re-stamped\n' % (n, parent_traj))
        for t, r in zip(stamps, rows[:n]):
            f.write('%.6f %s\n' % (t, ' '.join(r[1:8])))


def make_table(results, method_names):
    """ATE in cm per method, then ms per frame as 'wall / CPU' (CPU: user + system time of all threads)."""
    head = '| sequence | frames | ' + ' | '.join('%s ATE cm' % m for m in method_names) + ' | ' + \
           ' | '.join('%s ms/frame wall / CPU' % m for m in method_names) + ' |\n'
    head += '|---|---:|' + '---:|' * (2 * len(method_names)) + '\n'
    rows = []
    for name, e in results['sequences'].items():
        if e.get('skipped'):
            rows.append('| %s | skipped |%s\n' % (name, ' |' * (2 * len(method_names))))
            continue
        ate, ms = [], []
        for m in method_names:
            r = e['methods'].get(m, {})
            ate.append('%.2f' % (100 * r['ate_m']) if 'ate_m' in r else 'failed')
            ms.append('%.0f / %.0f' % (r['ms_per_frame'], r['cpu_ms_per_frame']) if 'ms_per_frame' in r else '-')
        note = ''
        froms = {e['methods'][m].get('from') for m in method_names if m in e['methods']} - {None}
        if froms:
            note = ' (first %d frames of the %s run)' % (e['frames'], ', '.join(sorted(froms)))
        rows.append('| %s%s | %d | %s | %s |\n' % (name, note, e['frames'], ' | '.join(ate), ' | '.join(ms)))
    return head + ''.join(rows)


# ---------------------------------------------------------------- selftest

def selftest():
    import numpy as np
    rng = np.random.default_rng(1)
    # Horn: a known rotation and translation are recovered exactly.
    pts = rng.uniform(-1, 1, size=(50, 3))
    a = 0.7
    r = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    r2, c2 = horn(pts, pts @ r.T + [0.3, -0.2, 1.0])
    assert np.allclose(r2, r) and np.allclose(c2, [0.3, -0.2, 1.0]), 'horn'
    # Quaternion of that rotation: about z by a.
    q = quaternion(r.tolist())
    assert abs(q[2] - math.sin(a / 2)) < 1e-12 and abs(q[3] - math.cos(a / 2)) < 1e-12, 'quaternion'
    # Pyramid: means of consistent blocks, NaN across a jump.
    d = np.array([[1, 1, 2, 2.5], [1, 1, 2, 2]], dtype=np.float32)
    p = pyramid_down(d, 0.07)
    assert p.shape == (1, 2) and p[0, 0] == 1 and math.isnan(p[0, 1]), 'pyramid'
    # Matching within 0.02 s and the aligned errors of a shifted copy are zero.
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        gt, est = os.path.join(tmp, 'gt.txt'), os.path.join(tmp, 'est.txt')
        with open(gt, 'w') as f, open(est, 'w') as g:
            for i in range(20):
                x = (math.cos(i / 5), math.sin(i / 5), i / 20)
                f.write('%.6f %f %f %f 0 0 0 1\n' % (i / 30, *x))
                g.write('%.6f %f %f %f 0 0 0 1\n' % (i / 30 + 0.001, x[0] + 5, x[1], x[2]))
        _, errs = aligned_errors(est, gt)
        assert len(errs) == 20 and max(errs) < 1e-5, 'aligned errors'
        with open(est, 'w') as g:
            g.write('0 1 2 3\n')
        try:
            read_trajectory(est)
            raise AssertionError('bad trajectory accepted')
        except ValueError as e:
            assert 'expected 8' in str(e)
        svg = os.path.join(tmp, 'p.svg')
        svg_plot(svg, 'a <test>', {'x': [(0, 1.0), (1, 2.0)], 'y': []})
        text = open(svg).read()
        assert text.startswith('<svg') and '&lt;test&gt;' in text, 'svg'
    # Argument errors.
    ns = argparse.Namespace(tc=['bad'], tc_args=None)
    try:
        parse_configs(ns)
        raise AssertionError('--tc without = accepted')
    except UsageError as e:
        assert 'NAME=ARGS' in str(e)
    assert parse_configs(argparse.Namespace(tc=['a=--pyramid 3', 'b='], tc_args=None)) == \
        [('a', ['--pyramid', '3']), ('b', [])]
    print('peers.py selftest: ok')
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest='command', required=True)
    r = sub.add_parser('run', help='run the methods on the sequences and write the table and plots')
    r.add_argument('--track-camera', help='path to the track_camera binary')
    r.add_argument('--tc-args', help="flags for track_camera's single configuration, e.g. \"--pyramid 3\"")
    r.add_argument('--tc', action='append', metavar='NAME=ARGS',
                   help='a named track_camera configuration (repeatable): its columns side by side')
    r.add_argument('--evaluate', help='evaluate_trajectory binary (default: next to track_camera)')
    r.add_argument('--export-synthetic', help='export_synthetic binary (default: next to track_camera)')
    r.add_argument('--methods', default='track_camera,open3d', help='track_camera, open3d or both (default)')
    r.add_argument('--sequences', help='comma-separated names (default: all; --quick: %s)' % ','.join(QUICK))
    r.add_argument('--quick', action='store_true', help='first %d frames of %s' % (QUICK_FRAMES, ' and '.join(QUICK)))
    r.add_argument('--max-frames', type=int, help='at most N frames of each sequence')
    r.add_argument('--out', help='output folder (default bench/out/peers, or bench/out/peers-quick)')
    r.add_argument('--reuse', metavar='METHODS',
                   help='comma-separated methods whose earlier runs in --out (same command, trajectory present) '
                        'are scored again instead of re-run, e.g. after a change to the other methods only')
    r.add_argument('--no-prefix', action='store_true',
                   help='run redkitchen_300 and tab600 themselves, not as the first frames of the tab900 run')
    r.add_argument('--o3d-trunc', type=float, default=8.0, help="Open3D's truncation in voxels (default 8)")
    r.add_argument('--o3d-reject', type=float, default=0.0,
                   help="drop an Open3D step longer than this (m), as dense_slam's odometry_distance_thr; 0 = off")
    o = sub.add_parser('open3d', help='(internal) the Open3D loop on one sequence')
    o.add_argument('sequence')
    o.add_argument('trajectory')
    o.add_argument('--max-frames', type=int, default=0)
    o.add_argument('--o3d-trunc', type=float, default=8.0)
    o.add_argument('--o3d-reject', type=float, default=0.0)
    sub.add_parser('selftest', help="check the script's own parts (no Open3D, no data)")
    args = ap.parse_args()
    try:
        if args.command == 'selftest':
            return selftest()
        if args.command == 'open3d':
            if not os.path.isdir(args.sequence):
                raise UsageError('%s: not a directory' % args.sequence)
            n, seconds, cpu = run_open3d(args.sequence, args.trajectory, args.max_frames, args.o3d_trunc,
                                         args.o3d_reject, lambda m: print(m, flush=True))
            print('open3d loop seconds %.3f cpu %.3f over %d frames' % (seconds, cpu, n))
            return 0
        if args.out is None:
            args.out = os.path.join(HERE, 'out', 'peers-quick' if args.quick else 'peers')
        return run(args)
    except UsageError as e:
        print('peers.py: error: %s' % e, file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
