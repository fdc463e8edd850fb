#!/usr/bin/env python3
"""Generalisation benchmark: many generated dynamic sequences through the emfusion app.

Generates dynamic RGB-D sequences with the shared generator (shared/tools/dyngen.py): fully
synthetic rooms and composites on redkitchen_300 (also 'there and back' ones, see
bench/there_and_back.py), with other seeds, object mixes, speeds up to the generator's limits,
missed and false detections; and writes the app's own built-in scenes (synthetic:room,
synthetic:corridor) as sequences of the same kind with `emfusion export`. Runs the app on
each, then scores the runs against the ground truth and prints a table and a PASS/FAIL
summary per target. docs/benchmarks.md has the
commands, the sequence list and the metric definitions.

Steps (subcommands):
  list      the sequences (name, kind, generator command)
  generate  make the sequences that are missing (needs numpy, scipy, opencv: Debian's
            python3-numpy python3-scipy python3-opencv; installed with apt-get when missing and
            root; the built-in scenes need the app, --app); also writes
            <seq>/bench_labels.json, the per-frame label areas and detections the report needs,
            so that report needs numpy only
  export    copy generated sequences without colour and ground-truth masks (--to DIR), for a
            machine that cannot generate (run and report there with --work DIR)
  run       run the app on each generated sequence, and track_camera on each composite's base
            frames (the reference of the composites' camera target; --track-camera) and, with
            opencv, on each composite without its movers' pixels (a report info line); always
            re-runs
  report    score the runs and print the table and the summary (numpy only)
  all       generate, run, report
  errors    per estimate, its position and rotation error against its mover, frame by frame
            (every --every-th frame and those over --above metres): where tracking went wrong
  selftest  check the metric code on small hand-made cases
  compare   two files written by report --json: failed targets of each and every number that
            differs (an A/B of two settings run with --tag, say)

Examples:
  /usr/bin/python3 bench/generalisation.py all --backend cuda --jobs 2
  /usr/bin/python3 bench/generalisation.py all --quick --backend cpu
  python3 bench/generalisation.py report --only s201,s202
"""

import argparse
import concurrent.futures
import hashlib
import json
import os
import shlex
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from there_and_back import read_list  # noqa: E402  (the text-list reader both scripts use)

REPO = os.path.dirname(HERE)
# The shared folder (generator and redkitchen_300): ../shared beside the checkout, or where
# EMFUSION_SHARED_DIR says (a machine that has a copy elsewhere, such as the GPU machine).
SHARED = os.path.normpath(os.environ.get('EMFUSION_SHARED_DIR') or os.path.join(REPO, '..', 'shared'))
DYNGEN = os.path.join(SHARED, 'tools', 'dyngen.py')
KITCHEN = os.path.join(SHARED, 'data', 'redkitchen_300')

# The paper's visibility rule: at least 40x40 pixels of the object's ground-truth mask inside
# the image less a 20-pixel border.
BORDER = 20
MIN_AREA = 40 * 40
MAX_DIFF = 0.02        # s, timestamp association tolerance (as the app's eval)
MATCH_DISTANCE = 0.25  # m, as eval/object_matching.hpp
LOST_LIMIT_S = 1.0
COVERAGE_MIN = 0.90
OBJ_ATE_MAX = {'synthetic': 0.01, 'composite': 0.02}
CAM_ATE_MAX = {'synthetic': 0.005}
CAM_REFERENCE_MARGIN = 0.001  # m: a composite's camera may be this much worse than track_camera on its base

# 'fast' objects: 1 s moves at the largest length and angle the generator allows for them; their
# peaks reach about 0.42 m/s and 80 deg/s (measured on c213-fast), the most its planner makes
# under its limits of 0.5 m/s and 90 deg/s (it caps lengths and angles at 90 % of them).
FAST = 'move=30:angle=60'


def S(name, frames, seed, objects, **kw):
    d = dict(name=name, kind='synthetic', frames=frames, seed=seed, objects=objects)
    d.update(kw)
    return d


def B(name, scene, frames):
    """One of the app's built-in scenes, written by `emfusion export` with its simulated detector
    (its ground truth, masks and labels as a generated sequence's): scored as a synthetic room."""
    return dict(name=name, kind='synthetic', scene=scene, frames=frames)


def C(name, frames, seed, objects, base='redkitchen_300', **kw):
    d = dict(name=name, kind='composite', frames=frames, seed=seed, objects=objects, base=base)
    d.update(kw)
    return d


# The benchmark's sequences. frames: synthetic N; composite 'A:B' of the base (a there-and-back
# base 'tab600'/'tab900' is made by there_and_back.py from redkitchen_300).
SEQUENCES = [
    S('s201', 300, 201, 'cup:mug,car:toy_car,book:box,bottle:cylinder'),
    S('s202', 300, 202, 'donut:torus,teddy_bear:sphere,car:toy_car,cup:mug'),
    S('s203', 300, 203, 'bottle:capsule,sports_ball:sphere,book:round_box,car:toy_car'),
    S('s204-fast', 300, 204, ','.join('%s:%s' % (c, FAST) for c in
                                      ('car:toy_car', 'cup:mug', 'sports_ball:sphere'))),
    S('s205-noisy-detector', 300, 205, 'car:toy_car,cup:mug,book:box', p_miss=0.3, p_fp=0.3),
    S('s206-two-small', 300, 206, 'cup:mug:size=0.8,bottle:cylinder:size=0.8'),
    S('s207-long600', 600, 207, 'car:toy_car,cup:mug,teddy_bear:sphere,book:round_box'),
    S('s208-long900-fast', 900, 208, 'car:toy_car:%s,cup:mug,sports_ball:sphere:%s' % (FAST, FAST),
      p_miss=0.2, p_fp=0.1),
    C('c211', '0:300', 211, 'car:toy_car,cup:mug,book:box'),
    C('c212-noisy-detector', '0:300', 212, 'teddy_bear:sphere,bottle:cylinder,sports_ball:sphere',
      p_miss=0.3, p_fp=0.3),
    C('c213-fast', '0:300', 213, ','.join('%s:%s' % (c, FAST) for c in ('car:toy_car', 'cup:mug'))),
    C('c214-tab600', '0:600', 214, 'car:toy_car,cup:mug,book:round_box', base='tab600'),
    C('c215-tab900', '0:900', 215, 'teddy_bear:sphere,car:toy_car,bottle:capsule', base='tab900',
      p_miss=0.2, p_fp=0.1),
    # The app's own scenes: the room of the README's first command, and the corridor (an 11 m
    # walk past four movers; the young objects' border hold was made on it, docs/decisions.md).
    B('room', 'synthetic:room', 300),
    B('corridor', 'synthetic:corridor', 600),
]

# --holdout: sequences of the same kinds that no change was tuned on (other seeds, mixes, speeds
# and detectors): run them after a change that helped on the list above, to see that it helps
# on sequences it was not made on, as the "sequences you do not have" will be. A failure
# found here is studied on a copy added to SEQUENCES, so that this list stays unseen.
HOLDOUT = [
    S('h231', 300, 231, 'cup:mug,book:round_box,teddy_bear:sphere'),
    S('h232-fast450', 450, 232, 'car:toy_car:%s,bottle:capsule,donut:torus:%s' % (FAST, FAST)),
    S('h233-long600-noisy', 600, 233, 'sports_ball:sphere,cup:mug,car:toy_car,book:box', p_miss=0.2, p_fp=0.2),
    C('h234', '0:300', 234, 'cup:mug,teddy_bear:sphere,car:toy_car'),
    C('h235-tab600', '0:600', 235, 'book:box,bottle:cylinder,sports_ball:sphere:%s' % FAST, base='tab600'),
]

# --fresh: a second held-out set, made when the first had been looked into (h234's car, the
# forty-fourth session): run once on the code of the day it was made (the forty-fifth session,
# docs/benchmarks.md) and then, like HOLDOUT, only to check a change that helped elsewhere.
FRESH = [
    S('h241', 300, 241, 'bottle:cylinder,car:toy_car,sports_ball:sphere,cup:mug'),
    S('h242-fast450', 450, 242, 'book:box:%s,teddy_bear:sphere,donut:torus' % FAST),
    S('h243-long600', 600, 243, 'cup:mug,car:toy_car,bottle:capsule,book:round_box', p_miss=0.2, p_fp=0.1),
    C('h244-noisy', '0:300', 244, 'book:round_box,cup:mug,bottle:capsule', p_miss=0.3, p_fp=0.2),
    C('h245-tab900', '0:900', 245, 'car:toy_car,teddy_bear:sphere:%s,book:box' % FAST, base='tab900'),
]

# --quick: short sequences that check the whole pipeline in minutes on a CPU (the third one
# around the turn of a there-and-back base).
QUICK = [
    S('q-synthetic90', 90, 301, 'car:toy_car,cup:mug', det_every=15),
    C('q-composite90', '0:90', 302, 'car:toy_car,book:box', det_every=15),
    C('q-tab-turn90', '255:345', 303, 'cup:mug,book:round_box', base='tab600', det_every=15),
]


# ----------------------------------------------------------------------------- small helpers

def log(*a):
    print(*a, flush=True)


def seq_params(s):
    """Everything that decides the generated frames (the cache key)."""
    if s.get('scene'):
        return dict(kind=s['kind'], scene=s['scene'], frames=s['frames'])
    return dict(kind=s['kind'], frames=s['frames'], seed=s['seed'], objects=s['objects'],
                base=s.get('base'), det_every=s.get('det_every', 30), p_miss=s.get('p_miss', 0.1),
                p_fp=s.get('p_fp', 0.05))


def seq_dir(work, s):
    key = hashlib.sha1(json.dumps(seq_params(s), sort_keys=True).encode()).hexdigest()[:8]
    return os.path.join(work, 'seq', '%s-%s' % (s['name'], key))


def base_dir(work, base):
    if base == 'redkitchen_300':
        return KITCHEN
    return os.path.join(work, 'base', base)


def generator_python():
    """The interpreter dyngen runs with: this one when it has numpy, scipy and cv2, else Debian's."""
    probe = [sys.executable, '-c', 'import numpy, scipy, cv2']
    if subprocess.run(probe, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode == 0:
        return sys.executable
    return '/usr/bin/python3'


def dyngen_command(s, out, base, jobs):
    p = seq_params(s)
    cmd = [generator_python(), DYNGEN, p['kind'], '--out', out, '--frames', str(p['frames']),
           '--objects', p['objects'], '--seed', str(p['seed']), '--det-every', str(p['det_every']),
           '--p-miss', str(p['p_miss']), '--p-fp', str(p['p_fp']), '--jobs', str(jobs), '--no-preview']
    if p['kind'] == 'composite':
        cmd[3:3] = ['--base', base]
    return cmd


def export_command(app, s, out):
    """The app's export of a built-in scene (B)."""
    return [app, 'export', s['scene'], out, '--max-frames', str(s['frames'])]


def generation_command(args, s, out):
    """What makes sequence s in `out`: the generator, or the app for a built-in scene."""
    if s.get('scene'):
        return export_command(args.app, s, out)
    base = base_dir(args.work, s['base']) if s['kind'] == 'composite' else None
    return dyngen_command(s, out, base, args.gen_jobs)


def sequence_info(seq):
    """The objects in label order and the detector's period: the generator's dyngen.json, or the
    scene.json of `emfusion export` (a built-in scene)."""
    for name in ('dyngen.json', 'scene.json'):
        p = os.path.join(seq, name)
        if os.path.isfile(p):
            try:
                return json.load(open(p))
            except ValueError as e:
                raise SystemExit('%s: not valid JSON: %s' % (p, e))
    raise SystemExit('%s: neither dyngen.json nor scene.json: not a generated sequence' % seq)


def ensure_generator_packages():
    """numpy, scipy and cv2 for /usr/bin/python3 (Debian packages, installed when root)."""
    probe = [generator_python(), '-c', 'import numpy, scipy, cv2']
    if subprocess.run(probe, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode == 0:
        return
    if os.geteuid() != 0:
        raise SystemExit('generate needs python3-numpy python3-scipy python3-opencv for /usr/bin/python3; '
                         'install them as root (apt-get install ...)')
    log('installing python3-numpy python3-scipy python3-opencv with apt-get')
    subprocess.run(['apt-get', 'update', '-q'], check=True)
    subprocess.run(['apt-get', 'install', '-y', '-q', 'python3-numpy', 'python3-scipy', 'python3-opencv'],
                   check=True, env=dict(os.environ, DEBIAN_FRONTEND='noninteractive'))


# ----------------------------------------------------------------------------- ground-truth labels

def inner_area(labels, k, border=BORDER):
    """Pixels of label k inside the image less a `border`-pixel border."""
    return int((labels[border:labels.shape[0] - border, border:labels.shape[1] - border] == k).sum())


def detected_labels(det, gt, ids):
    """Ground-truth labels that detector instances `ids` of image `det` stand for: an instance is
    object k when at least half of its pixels lie on k's ground-truth mask."""
    import numpy as np
    out = set()
    for i in ids:
        m = det == i
        n = int(m.sum())
        if n == 0:
            continue
        counts = np.bincount(gt[m].ravel(), minlength=256)
        counts[0] = 0
        k = int(counts.argmax())
        if k > 0 and counts[k] >= 0.5 * n:
            out.add(k)
    return sorted(out)


def write_labels_summary(seq):
    """<seq>/bench_labels.json: per frame and object the ground-truth mask area (whole image
    and inside the 20-pixel border) and, on detector frames, which objects the simulated
    detector reported. Needs cv2; the report then needs numpy only."""
    import cv2
    import numpy as np
    info = sequence_info(seq)
    names = [o['name'] for o in info['objects']]
    gt_rows = read_list(os.path.join(seq, 'masks_gt', 'masks.txt'))
    det_rows = {r[0]: r for r in read_list(os.path.join(seq, 'masks', 'masks.txt'))}
    frames = []
    for r in gt_rows:
        lab = cv2.imread(os.path.join(seq, 'masks_gt', r[1]), cv2.IMREAD_UNCHANGED)
        area = [int((lab == k).sum()) for k in range(1, len(names) + 1)]
        inner = [inner_area(lab, k) for k in range(1, len(names) + 1)]
        fr = dict(t=r[0], area=area, inner=inner)
        if r[0] in det_rows:
            d = det_rows[r[0]]
            det = cv2.imread(os.path.join(seq, 'masks', d[1]), cv2.IMREAD_UNCHANGED)
            ids = [int(e.split(':')[0]) for e in d[2:]]
            fr['detected'] = detected_labels(det, lab, ids)
            fr['detections'] = len(ids)
        frames.append(fr)
    out = dict(border=BORDER, objects=names, det_every=info['det_every'], frames=frames)
    tmp = os.path.join(seq, 'bench_labels.json.tmp')
    with open(tmp, 'w') as f:
        json.dump(out, f, separators=(',', ':'))
    os.replace(tmp, os.path.join(seq, 'bench_labels.json'))


# ----------------------------------------------------------------------------- generate

def generate(args, seqs):
    ensure_generator_packages()
    for s in seqs:
        out = seq_dir(args.work, s)
        done = os.path.isfile(os.path.join(out, 'bench_params.json'))
        if done and os.path.isfile(os.path.join(out, 'bench_labels.json')):
            log('[generate] %s: cached in %s' % (s['name'], out))
            continue
        if not done:
            if s.get('scene') and not os.path.isfile(args.app):
                raise SystemExit('[generate] %s: the built-in scene is written by the app, not found: %s '
                                 '(build it, or pass --app)' % (s['name'], args.app))
            if s['kind'] == 'composite':
                base = base_dir(args.work, s['base'])
                if s['base'] != 'redkitchen_300' and not os.path.isfile(os.path.join(base, 'groundtruth.txt')):
                    n = int(s['base'][3:])
                    cmd = ['/usr/bin/python3', os.path.join(HERE, 'there_and_back.py'), '--base', KITCHEN,
                           '--frames', str(n), '--out', base]
                    log('[generate] ' + ' '.join(shlex.quote(c) for c in cmd))
                    subprocess.run(cmd, check=True)
            if os.path.isdir(out):
                subprocess.run(['rm', '-rf', '--', out], check=True)   # a half-written earlier try
            os.makedirs(out)
            cmd = generation_command(args, s, out)
            log('[generate] %s: %s' % (s['name'], ' '.join(shlex.quote(c) for c in cmd)))
            t0 = time.time()
            with open(os.path.join(out, 'bench_generate.log'), 'w') as lf:
                r = subprocess.run(cmd, stdout=lf, stderr=subprocess.STDOUT)
            if r.returncode != 0:
                raise SystemExit('[generate] %s failed (rc %d), see %s' % (
                    s['name'], r.returncode, os.path.join(out, 'bench_generate.log')))
            with open(os.path.join(out, 'bench_params.json'), 'w') as f:
                json.dump(dict(params=seq_params(s), name=s['name'], command=cmd,
                               seconds=round(time.time() - t0, 1)), f, indent=1)
            log('[generate] %s: %.0f s' % (s['name'], time.time() - t0))
        labels_summary(out)


def labels_summary(seq):
    """write_labels_summary here, or through /usr/bin/python3 where this interpreter has no cv2."""
    try:
        import cv2  # noqa: F401
        import numpy  # noqa: F401
    except ImportError:
        subprocess.run([generator_python(), os.path.abspath(__file__), '_labels', seq], check=True)
        return
    write_labels_summary(seq)


# ----------------------------------------------------------------------------- export

# What run and report read from a generated sequence: no rgb/ (the app tracks on depth and reads
# a sequence without colour) and no masks_gt/ (bench_labels.json holds what the report needs).
EXPORT_FILES = ['depth.txt', 'calibration.txt', 'groundtruth.txt', 'dyngen.json', 'scene.json',
                'bench_labels.json', 'bench_params.json', 'README.txt']
EXPORT_DIRS = ['depth', 'masks', 'groundtruth_objects']


def export(args, seqs):
    """Copies the generated sequences, without colour and ground-truth masks, to --to DIR in the
    layout of --work, for a machine that cannot generate: there run `run --work DIR` and `report
    --work DIR`."""
    import shutil
    if not args.to:
        raise SystemExit('export needs --to DIR')
    total = 0
    for s in seqs:
        src = seq_dir(args.work, s)
        if not os.path.isfile(os.path.join(src, 'bench_labels.json')):
            raise SystemExit('[export] %s is not generated (run the generate step)' % s['name'])
        dst = seq_dir(os.path.abspath(args.to), s)
        if os.path.isdir(dst):
            shutil.rmtree(dst)
        os.makedirs(dst)
        for f in EXPORT_FILES:
            if os.path.isfile(os.path.join(src, f)):
                shutil.copyfile(os.path.join(src, f), os.path.join(dst, f))
        for d in EXPORT_DIRS:
            shutil.copytree(os.path.join(src, d), os.path.join(dst, d))
        size = sum(os.path.getsize(os.path.join(r, f)) for r, _, fs in os.walk(dst) for f in fs)
        total += size
        log('[export] %s: %.1f MiB -> %s' % (s['name'], size / 2 ** 20, dst))
    log('[export] %.1f MiB in all' % (total / 2 ** 20))


# ----------------------------------------------------------------------------- run

def run_dir(work, s, backend):
    return os.path.join(work, 'runs', backend, os.path.basename(seq_dir(work, s)))


def run_logged(cmd, log_path):
    """Runs cmd (OMP_WAIT_POLICY=passive unless set) with its output and the command line in
    log_path; returns its exit status and seconds."""
    env = dict(os.environ)
    env.setdefault('OMP_WAIT_POLICY', 'passive')
    t0 = time.time()
    with open(log_path, 'w') as lf:
        lf.write(' '.join(shlex.quote(c) for c in cmd) + '\n')
        lf.flush()
        r = subprocess.run(cmd, stdout=lf, stderr=subprocess.STDOUT, env=env)
    return r.returncode, time.time() - t0


def run_one(args, s):
    seq = seq_dir(args.work, s)
    out = run_dir(args.work, s, args.backend + args.tag)
    if not os.path.isfile(os.path.join(seq, 'bench_params.json')):
        return s['name'], 'not generated (run the generate step)', 0.0
    if os.path.isdir(out):
        subprocess.run(['rm', '-rf', '--', out], check=True)
    os.makedirs(out)
    cmd = [args.app, 'run', seq, '--output', out, '--backend', args.backend, '--verbose'] + args.app_args
    rc, dt = run_logged(cmd, os.path.join(out, 'bench_run.log'))
    with open(os.path.join(out, 'bench_run.json'), 'w') as f:
        json.dump(dict(command=cmd, rc=rc, seconds=round(dt, 1)), f, indent=1)
    return s['name'], ('ok' if rc == 0 else 'failed rc %d, see %s/bench_run.log' % (rc, out)), dt


def reference_frames(s):
    """The frames of a composite's base that track_camera's reference runs on: N when the
    composite is the base's frames 0:N, else None (track_camera starts at a sequence's first
    frame)."""
    if s['kind'] != 'composite':
        return None
    first, _, last = str(s['frames']).partition(':')
    return int(last) if first == '0' and last.isdigit() else None


def reference_path(work, s, backend):
    """Where track_camera's trajectory on composite s's base frames is written (one per base and
    frame count: composites on the same frames share it), or None (reference_frames)."""
    n = reference_frames(s)
    if n is None:
        return None
    return os.path.join(work, 'runs', backend, 'track_camera', '%s-%d.txt' % (s['base'], n))


def run_reference(args, base, n, path):
    """track_camera (its defaults) on the first n frames of `base`: the camera ATE a tracker of the
    static scene gets on the frames a composite shows (the issue's camera target)."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    cmd = [args.track_camera, base_dir(args.work, base), path, '--backend', args.backend, '--max-frames', str(n)]
    rc, dt = run_logged(cmd, path + '.log')
    if rc != 0 and os.path.isfile(path):
        os.remove(path)
    return 'track_camera %s:%d' % (base, n), 'ok' if rc == 0 else 'failed rc %d, see %s.log' % (rc, path), dt


def movers_removed_path(work, s, backend):
    """Where track_camera's trajectory on composite s with its movers' pixels removed
    (run_movers_removed) is written, one per composite; None for a synthetic room."""
    if s['kind'] != 'composite':
        return None
    return os.path.join(work, 'runs', backend, 'track_camera', '%s-movers-removed.txt' % s['name'])


def remove_movers(depth, labels):
    """A copy of depth image `depth` with no measurement (0) wherever the ground-truth label
    image `labels` of the same frame shows a mover (label > 0)."""
    if depth.shape != labels.shape:
        raise ValueError('depth %s and labels %s differ in size' % (depth.shape, labels.shape))
    out = depth.copy()
    out[labels > 0] = 0
    return out


def write_movers_removed(seq, dst):
    """A sequence folder at dst that is `seq` with every mover's pixels taken out of its depth
    (remove_movers with masks_gt/ of the same file name): every entry of seq linked, but depth/,
    written anew. Needs cv2."""
    import cv2
    os.makedirs(os.path.join(dst, 'depth'))
    for e in os.listdir(seq):
        if e != 'depth':
            os.symlink(os.path.join(seq, e), os.path.join(dst, e))
    for fn in sorted(os.listdir(os.path.join(seq, 'depth'))):
        dp, lp = os.path.join(seq, 'depth', fn), os.path.join(seq, 'masks_gt', fn)
        if not os.path.isfile(lp):
            raise SystemExit('%s: no ground-truth mask for %s' % (lp, dp))
        depth, labels = cv2.imread(dp, cv2.IMREAD_UNCHANGED), cv2.imread(lp, cv2.IMREAD_UNCHANGED)
        if depth is None or labels is None:
            raise SystemExit('cannot read %s' % (lp if depth is not None else dp))
        try:
            out = remove_movers(depth, labels)
        except ValueError as e:
            raise SystemExit('%s against %s: %s' % (dp, lp, e))
        if not cv2.imwrite(os.path.join(dst, 'depth', fn), out):
            raise SystemExit('cannot write %s' % os.path.join(dst, 'depth', fn))


def run_movers_removed(args, s, path):
    """track_camera (its defaults) on composite s with the depth of its movers' pixels removed (the
    ground-truth masks): the camera ATE of a tracker told exactly which pixels move, which only the
    background the movers hide keeps from the base frames' reference. Not a target: the report's
    info line. The copy of the sequence lives beside `path` while it runs."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    name = 'track_camera %s without its movers' % s['name']
    tmp = path + '.seq'
    t0 = time.time()
    subprocess.run(['rm', '-rf', '--', tmp], check=True)
    try:
        write_movers_removed(seq_dir(args.work, s), tmp)
        rc, _ = run_logged([args.track_camera, tmp, path, '--backend', args.backend], path + '.log')
    except SystemExit as e:  # a sequence that cannot be copied fails this run, not the others
        return name, 'failed: %s' % e, time.time() - t0
    finally:
        subprocess.run(['rm', '-rf', '--', tmp], check=True)
    if rc != 0 and os.path.isfile(path):
        os.remove(path)
    return name, 'ok' if rc == 0 else 'failed rc %d, see %s.log' % (rc, path), time.time() - t0


def run(args, seqs):
    if not os.path.isfile(args.app):
        raise SystemExit('app not found: %s (build it: cmake --build --preset release --target emfusion_app, '
                         'or pass --app)' % args.app)
    # The composites' reference: track_camera on their base frames, once per base and frame count.
    references = {}
    for s in seqs:
        path = reference_path(args.work, s, args.backend + args.tag)
        if path and os.path.isfile(os.path.join(seq_dir(args.work, s), 'bench_params.json')):
            references[path] = (s['base'], reference_frames(s))
    # And on each composite with its movers' pixels removed (an info line of the report).
    removed = []
    for s in seqs:
        seq = seq_dir(args.work, s)
        if s['kind'] != 'composite' or not os.path.isfile(os.path.join(seq, 'bench_params.json')):
            continue
        if os.path.isdir(os.path.join(seq, 'masks_gt')):
            removed.append((s, movers_removed_path(args.work, s, args.backend + args.tag)))
        else:
            log('[run] %s: no masks_gt/ (an exported copy): track_camera without its movers is not run' % s['name'])
    if (references or removed) and not os.path.isfile(args.track_camera):
        log('[run] track_camera not found (%s; --track-camera): the composites\' camera target is not scored'
            % args.track_camera)
        references, removed = {}, []
    if removed:
        try:
            import cv2  # noqa: F401
        except ImportError:
            log('[run] no cv2 for %s: track_camera without the movers is not run (the generate step installs '
                'it)' % sys.executable)
            removed = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        futs = [pool.submit(run_one, args, s) for s in seqs]
        futs += [pool.submit(run_reference, args, base, n, path) for path, (base, n) in references.items()]
        futs += [pool.submit(run_movers_removed, args, s, path) for s, path in removed]
        for fu in concurrent.futures.as_completed(futs):
            name, status, dt = fu.result()
            log('[run] %s: %s (%.0f s)' % (name, status, dt))


# ----------------------------------------------------------------------------- metrics (numpy only)

def quat_to_matrix(q):
    import numpy as np
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def read_tum(path):
    """(timestamps (n,), poses (n,4,4)) of a TUM trajectory, body-to-world."""
    import numpy as np
    rows = read_list(path)
    t = np.array([float(r[0]) for r in rows])
    T = np.tile(np.eye(4), (len(rows), 1, 1))
    for i, r in enumerate(rows):
        v = [float(x) for x in r[1:8]]
        T[i, :3, :3] = quat_to_matrix(np.array(v[3:7]))
        T[i, :3, 3] = v[:3]
    return t, T


def associate(t_est, t_gt, max_difference=MAX_DIFF):
    """TUM associate.py as eval/trajectory.hpp: every pair at most max_difference apart is a
    candidate, taken greedily by smallest difference, each pose once; sorted by estimate time."""
    import numpy as np
    order = np.argsort(t_gt, kind='stable')
    tg = np.asarray(t_gt)[order]
    cands = []
    for e, t in enumerate(t_est):
        lo = int(np.searchsorted(tg, t - max_difference, 'left'))
        hi = int(np.searchsorted(tg, t + max_difference, 'right'))
        for j in range(lo, hi):
            d = abs(tg[j] - t)
            if d <= max_difference:
                g = int(order[j])
                cands.append((d, t, t_gt[g], e, g))
    cands.sort()
    used_e, used_g, out = set(), set(), []
    for d, _, _, e, g in cands:
        if e in used_e or g in used_g:
            continue
        used_e.add(e)
        used_g.add(g)
        out.append((e, g))
    out.sort(key=lambda m: (t_est[m[0]], m[0]))
    return out


def nearest(t_sorted, t):
    """Index into the sorted array of the value nearest t (the earlier on a tie)."""
    import numpy as np
    j = int(np.searchsorted(t_sorted, t, 'left'))
    if j == len(t_sorted):
        return j - 1
    if j == 0:
        return 0
    return j - 1 if t - t_sorted[j - 1] <= t_sorted[j] - t else j


def camera_at(cam, t):
    """Index of the camera pose nearest t within MAX_DIFF, else None (cam: sorted (t, T))."""
    if len(cam[0]) == 0:
        return None
    k = nearest(cam[0], t)
    return k if abs(cam[0][k] - t) <= MAX_DIFF else None


def align_rigid(src, tgt):
    """R, t minimising sum |R src_i + t - tgt_i|^2 (Umeyama/Horn without scale, proper rotation)."""
    import numpy as np
    src, tgt = np.asarray(src, float), np.asarray(tgt, float)
    ms, mt = src.mean(0), tgt.mean(0)
    H = (tgt - mt).T @ (src - ms)
    U, _, Vt = np.linalg.svd(H)
    D = np.eye(3)
    D[2, 2] = 1.0 if np.linalg.det(U @ Vt) >= 0 else -1.0
    R = U @ D @ Vt
    return R, mt - R @ ms


def ate_rmse(est_pos, gt_pos):
    import numpy as np
    R, t = align_rigid(est_pos, gt_pos)
    e = np.linalg.norm(np.asarray(est_pos) @ R.T + t - np.asarray(gt_pos), axis=1)
    return float(np.sqrt(np.mean(e ** 2)))


def camera_ate(est_cam, gt_cam):
    m = associate(est_cam[0], gt_cam[0])
    if len(m) < 3:
        return None
    return ate_rmse([est_cam[1][e][:3, 3] for e, _ in m], [gt_cam[1][g][:3, 3] for _, g in m])


def origin_distance(est_cam, gt_cam, est_obj, gt_obj):
    """Mean camera-frame distance of the two object origins over their common frames and the
    number of frames (eval/object_matching.hpp, origin_distance)."""
    import numpy as np
    total, n = 0.0, 0
    for e, g in associate(est_obj[0], gt_obj[0]):
        ec, gc = camera_at(est_cam, est_obj[0][e]), camera_at(gt_cam, gt_obj[0][g])
        if ec is None or gc is None:
            continue
        pe = (np.linalg.inv(est_cam[1][ec]) @ est_obj[1][e])[:3, 3]
        pg = (np.linalg.inv(gt_cam[1][gc]) @ gt_obj[1][g])[:3, 3]
        total += float(np.linalg.norm(pe - pg))
        n += 1
    return (total / n if n else float('inf')), n


def object_offset(est_cam, gt_cam, est_obj, gt_obj, m):
    """The constant object-frame offset C that takes the estimate onto the truth through the cameras
    at the first pair of `m` (associated pose indices, in time order) with both cameras; None if
    there is none."""
    import numpy as np
    for e, g in m:
        ec, gc = camera_at(est_cam, est_obj[0][e]), camera_at(gt_cam, gt_obj[0][g])
        if ec is not None and gc is not None:
            return np.linalg.inv(est_obj[1][e]) @ est_cam[1][ec] @ np.linalg.inv(gt_cam[1][gc]) @ gt_obj[1][g]
    return None


def object_ate(est_cam, gt_cam, est_obj, gt_obj):
    """Object ATE (eval/object_ate.hpp): offset C through the cameras at the first common frame,
    then the rigid ATE of est_obj(t) C against gt_obj(t). Returns (rmse, matched) or None."""
    m = associate(est_obj[0], gt_obj[0])
    if len(m) < 3:
        return None
    m.sort(key=lambda p: gt_obj[0][p[1]])
    Cm = object_offset(est_cam, gt_cam, est_obj, gt_obj, m)
    if Cm is None:
        return None
    est_pos = [(est_obj[1][e] @ Cm)[:3, 3] for e, _ in m]
    gt_pos = [gt_obj[1][g][:3, 3] for _, g in m]
    return ate_rmse(est_pos, gt_pos), len(m)


def through_true_camera(est_cam, gt_cam, est_obj):
    """est_obj placed in the world through the true camera: each pose gt_cam(t) est_cam(t)^-1
    est_obj(t), the object as its own tracking saw it relative to the camera. Its object ATE
    leaves out the camera's drift, which the world-frame ATE includes."""
    import numpy as np
    keep, poses = [], []
    for k, t in enumerate(est_obj[0]):
        ec, gc = camera_at(est_cam, t), camera_at(gt_cam, t)
        if ec is not None and gc is not None:
            keep.append(k)
            poses.append(gt_cam[1][gc] @ np.linalg.inv(est_cam[1][ec]) @ est_obj[1][k])
    return est_obj[0][keep], np.array(poses).reshape(-1, 4, 4)


def match_objects(est_cam, gt_cam, estimates, truth):
    """eval/object_matching.hpp: each estimate goes to the ground-truth object whose origin is
    nearest in the camera frame (mean over >= 3 common frames, under MATCH_DISTANCE); a truth
    object may collect several. Returns {truth name: [estimate ids]} and the unmatched ids."""
    by = {n: [] for n in truth}
    unmatched = []
    for i in sorted(estimates):
        best, best_d = None, MATCH_DISTANCE
        for n in sorted(truth):
            d, k = origin_distance(est_cam, gt_cam, estimates[i], truth[n])
            if k >= 3 and d < best_d:
                best, best_d = n, d
        if best is None:
            unmatched.append(i)
        else:
            by[best].append(i)
    return by, unmatched


def frames_of(traj, frame_t):
    """Frame indices (into frame_t, sorted) at which trajectory `traj` has a pose."""
    out = set()
    for t in traj[0]:
        k = nearest(frame_t, t)
        if abs(frame_t[k] - t) <= MAX_DIFF:
            out.add(k)
    return out


def visible_frames(labels, k, min_area=MIN_AREA):
    """Frames in which object label k (1-based) is visible by the paper's rule."""
    return [i for i, fr in enumerate(labels['frames']) if fr['inner'][k - 1] >= min_area]


def longest_run(flags):
    best = cur = 0
    for f in flags:
        cur = cur + 1 if f else 0
        best = max(best, cur)
    return best


def object_metrics(name, k, labels, frame_t, fps, det_every, est_frames, kind, creation=None):
    """The per-object numbers that need no poses. est_frames: {estimate id: set of frames};
    creation: {estimate id: frame the system created it} where run.json says (an estimate's
    trajectory can begin before its creation: the app tracks new objects back through the
    frames it kept, track_back_frames), else its first frame."""
    n = len(frame_t)
    vis = visible_frames(labels, k)
    visset = set(vis)
    alive = [0] * n
    for fs in est_frames.values():
        for f in fs:
            alive[f] += 1
    r = dict(name=name, visible=len(vis), visible_any=sum(1 for fr in labels['frames'] if fr['area'][k - 1] > 0),
             fragments=len(est_frames), duplicate_frames=sum(1 for a in alive if a >= 2))
    creation = creation or {}
    created = min((creation.get(i, min(fs)) for i, fs in est_frames.items() if fs), default=None)
    r['first_visible'] = vis[0] if vis else None
    r['created'] = created
    r['coverage'] = (sum(1 for f in vis if alive[f] > 0) / len(vis)) if vis else None
    # The same from the first estimate on: what coverage leaves out when a missed first
    # detection put off the creation (the frames before it cannot have an estimate).
    after = [f for f in vis if created is not None and f >= created]
    r['coverage_from_creation'] = (sum(1 for f in after if alive[f] > 0) / len(after)) if after else None
    # Lost: longest run of consecutive frames, after the first creation, in which the object is
    # visible and no estimate of it exists (a frame where it is not visible ends a run).
    start = created if created is not None else n
    r['lost_frames'] = longest_run([(f >= start and f in visset and alive[f] == 0) for f in range(n)])
    r['lost_s'] = r['lost_frames'] / fps
    # Creation: frames from first being visible to the first estimate; allowed one detector
    # interval plus one per detector frame on which it was visible but not detected (missed).
    if vis:
        end = created if created is not None else n
        missed = 0
        for f, fr in enumerate(labels['frames']):
            if vis[0] <= f < end and 'detected' in fr and f in visset and k not in fr['detected']:
                missed += 1
        r['missed_detections'] = missed
        r['creation_allowed'] = det_every * (1 + missed)
        r['creation_delay'] = (created - vis[0]) if created is not None else None
    return r


def run_objects(path):
    """run.json's "objects" entries (io/run_json.hpp); none when there is no run.json."""
    if not os.path.isfile(path):
        return []
    try:
        return json.load(open(path)).get('objects', [])
    except ValueError as e:
        raise SystemExit('%s: not valid JSON: %s' % (path, e))


def merged_ids(path):
    """The ids run.json says were merged into another object (event "merged"); none
    when there is no run.json (io/run_json.hpp, read_merged_object_ids)."""
    return {int(o['id']) for o in run_objects(path)
            if any(e.get('event') == 'merged' for e in o.get('events', []))}


def creation_times(path):
    """{id: timestamp of its "created" event} from run.json; none when there is no run.json."""
    out = {}
    for o in run_objects(path):
        for e in o.get('events', []):
            if e.get('event') == 'created' and e.get('timestamp') is not None:
                out[int(o['id'])] = float(e['timestamp'])
    return out


def frame_errors(est_cam, gt_cam, est_obj, gt_obj):
    """Per common frame of an estimate and a truth object, in time order: (t, position error m,
    rotation error degrees) in the camera frame, the estimate carried by the constant object-frame
    offset of its first common frame (as object_ate): where tracking drifted, jumped or turned."""
    import numpy as np
    m = associate(est_obj[0], gt_obj[0])
    m.sort(key=lambda p: gt_obj[0][p[1]])
    C, rows = object_offset(est_cam, gt_cam, est_obj, gt_obj, m), []
    for e, g in m:
        ec, gc = camera_at(est_cam, est_obj[0][e]), camera_at(gt_cam, gt_obj[0][g])
        if ec is None or gc is None:
            continue
        pe = np.linalg.inv(est_cam[1][ec]) @ est_obj[1][e] @ C
        pg = np.linalg.inv(gt_cam[1][gc]) @ gt_obj[1][g]
        R = pe[:3, :3].T @ pg[:3, :3]
        angle = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))
        rows.append((float(gt_obj[0][g]), float(np.linalg.norm(pe[:3, 3] - pg[:3, 3])), angle))
    return rows


def load_run(seq, out):
    """A run's trajectories beside its sequence's truth: labels, frame times, fps, cameras, truth
    objects, estimates (merged ones left out) and their classes."""
    import numpy as np
    labels = json.load(open(os.path.join(seq, 'bench_labels.json')))
    info = sequence_info(seq)
    frame_t = np.array([float(fr['t']) for fr in labels['frames']])
    fps = 1.0 / float(np.median(np.diff(frame_t))) if len(frame_t) > 1 else 30.0
    gt_cam = read_tum(os.path.join(seq, 'groundtruth.txt'))
    est_cam = read_tum(os.path.join(out, 'camera.txt'))
    srt = lambda tr: (tr[0][np.argsort(tr[0], kind='stable')], tr[1][np.argsort(tr[0], kind='stable')])
    gt_cam, est_cam = srt(gt_cam), srt(est_cam)
    truth = {o['name']: read_tum(os.path.join(seq, 'groundtruth_objects', o['name'] + '.txt')) for o in info['objects']}
    estimates, classes = {}, {}
    merged = merged_ids(os.path.join(out, 'run.json'))
    created_t = creation_times(os.path.join(out, 'run.json'))
    for r in read_list(os.path.join(out, 'objects.txt')):
        i = int(r[0])
        if i in merged:  # its poses are in the trajectory of the object it was merged into
            continue
        classes[i] = r[1]
        p = os.path.join(out, 'objects', '%d.txt' % i)
        estimates[i] = read_tum(p) if os.path.isfile(p) else (np.zeros(0), np.zeros((0, 4, 4)))
    creation = {}
    for i, t in created_t.items():
        k = nearest(frame_t, t)
        if abs(frame_t[k] - t) <= MAX_DIFF:
            creation[i] = k
    return labels, frame_t, fps, gt_cam, est_cam, truth, estimates, classes, creation


def evaluate_run(seq, out, kind):
    """All numbers of one run: camera ATE, per truth object, false objects."""
    labels, frame_t, fps, gt_cam, est_cam, truth, estimates, classes, creation = load_run(seq, out)
    by, unmatched = match_objects(est_cam, gt_cam, estimates, truth)
    res = dict(camera_ate=camera_ate(est_cam, gt_cam), frames=len(frame_t), objects=[],
               false_objects=len(unmatched), false_object_frames=sum(len(estimates[i][0]) for i in unmatched),
               estimates=len(estimates))
    names = labels['objects']
    for k, n in enumerate(names, 1):
        ids = by.get(n, [])
        est_frames = {i: frames_of(estimates[i], frame_t) for i in ids}
        r = object_metrics(n, k, labels, frame_t, fps, labels['det_every'], est_frames, kind, creation)
        r['estimates'] = ids
        r['ate'] = None
        if ids:
            primary = max(ids, key=lambda i: (len(estimates[i][0]), -i))
            a = object_ate(est_cam, gt_cam, estimates[primary], truth[n])
            r['primary'] = primary
            if a is not None:
                r['ate'], r['ate_matched'] = a
            b = object_ate(gt_cam, gt_cam, through_true_camera(est_cam, gt_cam, estimates[primary]), truth[n])
            r['ate_true_camera'] = b[0] if b is not None else None
        res['objects'].append(r)
    return res


# ----------------------------------------------------------------------------- report

CRITERIA = [
    ('lost', 'no object lost for more than %.0f s while visible' % LOST_LIMIT_S),
    ('dup', 'no duplicates: one fragment per mover, never two estimates at once'),
    ('create', 'created within one detector interval of first visible plus missed detections'),
    ('obj_ate', 'object ATE < 1 cm (synthetic), < 2 cm (composite)'),
    ('coverage', 'coverage of visible frames >= %.0f %%' % (100 * COVERAGE_MIN)),
    ('cam_ate', 'camera ATE < 0.5 cm (synthetic rooms)'),
    ('cam_ref', 'camera ATE on composites within %.1f cm of track_camera on their base frames'
     % (100 * CAM_REFERENCE_MARGIN)),
]


def judge_object(r, kind):
    """PASS/FAIL (True/False) per object criterion; None where it does not apply (never visible)."""
    if not r['visible']:
        return dict(lost=None, dup=None, create=None, obj_ate=None, coverage=None)
    return dict(
        lost=r['created'] is not None and r['lost_s'] <= LOST_LIMIT_S,
        dup=r['fragments'] == 1 and r['duplicate_frames'] == 0,
        create=r['creation_delay'] is not None and r['creation_delay'] <= r['creation_allowed'],
        obj_ate=r['ate'] is not None and r['ate'] < OBJ_ATE_MAX[kind],
        coverage=r['coverage'] is not None and r['coverage'] >= COVERAGE_MIN)


def shown_value(c, r):
    """The number behind an object criterion, for the summary's list of failures."""
    if c == 'lost':
        return 'never created' if r['created'] is None else '%.2f s' % r['lost_s']
    if c == 'dup':
        return '%d fragments, %d duplicate frames' % (r['fragments'], r['duplicate_frames'])
    if c == 'create':
        return 'never created' if r['creation_delay'] is None else \
            'delay %d > %d frames' % (r['creation_delay'], r['creation_allowed'])
    if c == 'obj_ate':
        return 'no ATE' if r['ate'] is None else '%.2f cm' % (100 * r['ate'])
    return '%.0f %%' % (100 * r['coverage'])


def fmt(v, spec, none='-'):
    return none if v is None else spec % v


def reference_ate(args, s, seq):
    """The camera ATE of track_camera's reference run for composite s (run_reference) against
    the composite's ground truth, or None when there is none."""
    path = reference_path(args.work, s, args.backend + args.tag)
    if not path or not os.path.isfile(path):
        if path:
            log('[report] %s: no track_camera reference (%s): its camera target is not scored' % (s['name'], path))
        return None
    return camera_ate(read_tum(path), read_tum(os.path.join(seq, 'groundtruth.txt')))


def movers_removed_ate(args, s, seq):
    """The camera ATE of track_camera on composite s without its movers (run_movers_removed), or
    None when it did not run."""
    path = movers_removed_path(args.work, s, args.backend + args.tag)
    if not path or not os.path.isfile(path):
        return None
    return camera_ate(read_tum(path), read_tum(os.path.join(seq, 'groundtruth.txt')))


def hidden_background(results):
    """(name, result) of the composites that fail the camera reference target while their camera is
    within its margin of track_camera's on their frames without the movers' pixels: what the
    movers hide of the background, not the system, keeps them from the base frames' ATE."""
    return [(name, res) for name, res in results.items()
            if res.get('cam_ref_pass') is False and res.get('cam_movers_removed') is not None
            and res['camera_ate'] <= res['cam_movers_removed'] + CAM_REFERENCE_MARGIN]


def report(args, seqs):
    rows, results, unscored = [], {}, []
    for s in seqs:
        seq, out = seq_dir(args.work, s), run_dir(args.work, s, args.backend + args.tag)
        rj = os.path.join(out, 'bench_run.json')
        if not os.path.isfile(os.path.join(seq, 'bench_labels.json')):
            log('[report] %s: not generated' % s['name'])
            unscored.append(s['name'])
            continue
        if not os.path.isfile(rj):
            log('[report] %s: no run for backend %s' % (s['name'], args.backend))
            unscored.append(s['name'])
            continue
        run_info = json.load(open(rj))
        if run_info['rc'] != 0 or not os.path.isfile(os.path.join(out, 'camera.txt')):
            results[s['name']] = dict(kind=s['kind'], failed='app rc %d' % run_info['rc'])
            continue
        res = evaluate_run(seq, out, s['kind'])
        res['kind'] = s['kind']
        res['seconds'] = run_info['seconds']
        res['cam_pass'] = (res['camera_ate'] is not None and res['camera_ate'] < CAM_ATE_MAX['synthetic']) \
            if s['kind'] == 'synthetic' else None
        res['cam_reference'], res['cam_ref_pass'] = reference_ate(args, s, seq), None
        if res['cam_reference'] is not None and res['camera_ate'] is not None:
            res['cam_ref_pass'] = res['camera_ate'] <= res['cam_reference'] + CAM_REFERENCE_MARGIN
        res['cam_movers_removed'] = movers_removed_ate(args, s, seq) if s['kind'] == 'composite' else None
        for r in res['objects']:
            r['pass'] = judge_object(r, s['kind'])
        results[s['name']] = res

    hdr = ('sequence', 'kind', 'frames', 'cam ATE', 'object', 'vis (1px)', '1st vis', 'created', 'delay/allowed',
           'frag', 'dup fr', 'cover', 'lost', 'obj ATE', 'true cam', 'false', 'fails')
    for name, res in results.items():
        if 'failed' in res:
            rows.append((name, res['kind'], '-', res['failed']) + ('',) * (len(hdr) - 4))
            continue
        first = True
        for r in res['objects']:
            fails = ','.join(c for c, v in r['pass'].items() if v is False)
            if first and res['cam_pass'] is False:
                fails = ','.join(x for x in ('cam_ate', fails) if x)
            if first and res['cam_ref_pass'] is False:
                fails = ','.join(x for x in ('cam_ref', fails) if x)
            rows.append((
                name if first else '', res['kind'] if first else '', str(res['frames']) if first else '',
                fmt(res['camera_ate'] and 100 * res['camera_ate'], '%.2f cm') if first else '',
                r['name'], '%d (%d)' % (r['visible'], r['visible_any']), fmt(r['first_visible'], '%d'),
                fmt(r['created'], '%d'),
                '%s/%s' % (fmt(r.get('creation_delay'), '%d'), fmt(r.get('creation_allowed'), '%d')),
                str(r['fragments']), str(r['duplicate_frames']), fmt(r['coverage'] and 100 * r['coverage'], '%.0f %%'),
                '%.2f s' % r['lost_s'], fmt(r['ate'] and 100 * r['ate'], '%.2f cm'),
                fmt(r.get('ate_true_camera') and 100 * r['ate_true_camera'], '%.2f cm'),
                ('%d' % res['false_objects']) if first else '', fails or 'ok'))
            first = False
    print_table(hdr, rows, args.markdown)

    # summary per criterion
    print()
    print('Summary (%s backend, %d sequences scored):' % (args.backend, len(results)))
    all_pass = True
    for c, text in CRITERIA:
        ok = tot = 0
        bad = []
        for name, res in results.items():
            if 'failed' in res:
                tot += 1
                bad.append(name + ' (app failed)')
                continue
            if c == 'cam_ate':
                if res['cam_pass'] is None:
                    continue
                tot += 1
                ok += res['cam_pass']
                if not res['cam_pass']:
                    bad.append('%s %s' % (name, fmt(res['camera_ate'] and 100 * res['camera_ate'], '%.2f cm')))
                continue
            if c == 'cam_ref':
                if res.get('cam_ref_pass') is None:
                    continue
                tot += 1
                ok += res['cam_ref_pass']
                if not res['cam_ref_pass']:
                    bad.append('%s (%.2f cm, track_camera %.2f cm)' % (name, 100 * res['camera_ate'],
                                                                      100 * res['cam_reference']))
                continue
            for r in res['objects']:
                v = r['pass'][c]
                if v is None:
                    continue
                tot += 1
                ok += bool(v)
                if not v:
                    bad.append('%s/%s (%s)' % (name, r['name'], shown_value(c, r)))
        verdict = 'PASS' if tot and ok == tot else ('FAIL' if tot else 'n/a')
        all_pass &= verdict != 'FAIL'
        print('  %-4s %-82s %d/%d%s' % (verdict, text, ok, tot, ('  failing: ' + '; '.join(bad)) if bad else ''))
    # Object ATE failures that pass through the true camera: the camera's drift, not the object's
    # own tracking, puts them over the target.
    drift = ['%s/%s (%.2f -> %.2f cm)' % (name, r['name'], 100 * r['ate'], 100 * r['ate_true_camera'])
             for name, res in results.items() if 'failed' not in res for r in res['objects']
             if r['pass']['obj_ate'] is False and r['ate'] is not None and r.get('ate_true_camera') is not None
             and r['ate_true_camera'] < OBJ_ATE_MAX[res['kind']]]
    print('  info object ATE failures under the target through the true camera (camera drift): %s' %
          ('; '.join(drift) if drift else 'none'))
    # Coverage failures that the frames before a creation in time account for: the detector
    # missed the object's first detections, and no estimate can exist before the next one.
    late = ['%s/%s (%.0f -> %.0f %%)' % (name, r['name'], 100 * r['coverage'], 100 * r['coverage_from_creation'])
            for name, res in results.items() if 'failed' not in res for r in res['objects']
            if r['pass']['coverage'] is False and r['pass']['create'] is True
            and r.get('coverage_from_creation') is not None and r['coverage_from_creation'] >= COVERAGE_MIN]
    print('  info coverage failures met from the creation on (a missed first detection put it off): %s' %
          ('; '.join(late) if late else 'none'))
    hidden = ['%s (%.2f cm; track_camera %.2f cm on the base frames, %.2f cm without the movers\' pixels)' %
              (name, 100 * res['camera_ate'], 100 * res['cam_reference'], 100 * res['cam_movers_removed'])
              for name, res in hidden_background(results)]
    print('  info camera reference failures that track_camera shares on the frames without the movers\' pixels '
          '(the background they hide): %s' % ('; '.join(hidden) if hidden else 'none'))
    nf = sum(res.get('false_objects', 0) for res in results.values())
    print('  info false objects (estimates matched to no mover): %d' % nf)
    if unscored:
        print('  not scored (no sequence or no run): %s' % ', '.join(unscored))
    print('  overall: %s%s' % ('PASS' if all_pass and results else 'FAIL',
                               ' (on the %d scored sequences only)' % len(results) if unscored else ''))
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=1, default=lambda o: sorted(o) if isinstance(o, set) else str(o))
    return 0 if all_pass and results else 1


def print_table(hdr, rows, markdown):
    if markdown:
        print('| ' + ' | '.join(hdr) + ' |')
        print('|' + ' --- |' * len(hdr))
        for r in rows:
            print('| ' + ' | '.join(r) + ' |')
        return
    w = [max(len(str(x)) for x in col) for col in zip(hdr, *rows)] if rows else [len(h) for h in hdr]
    print('  '.join(h.ljust(w[i]) for i, h in enumerate(hdr)))
    for r in rows:
        print('  '.join(str(x).ljust(w[i]) for i, x in enumerate(r)))


# ----------------------------------------------------------------------------- errors

def errors(args, seqs):
    """Per estimate and frame, its error against the mover it is matched to (frame_errors): every
    --every-th frame, and every frame whose position error exceeds --above metres."""
    import numpy as np
    for s in seqs:
        seq, out = seq_dir(args.work, s), run_dir(args.work, s, args.backend + args.tag)
        if not os.path.isfile(os.path.join(seq, 'bench_labels.json')) or \
                not os.path.isfile(os.path.join(out, 'camera.txt')):
            log('[errors] %s: not generated or no run for backend %s%s' % (s['name'], args.backend, args.tag))
            continue
        labels, frame_t, fps, gt_cam, est_cam, truth, estimates, classes, _ = load_run(seq, out)
        by, _ = match_objects(est_cam, gt_cam, estimates, truth)
        for n in labels['objects']:
            for i in by.get(n, []):
                rows = frame_errors(est_cam, gt_cam, estimates[i], truth[n])
                print('%s: %s <- estimate %d (%s), %d frames' % (s['name'], n, i, classes[i], len(rows)))
                for k, (t, err, angle) in enumerate(rows):
                    frame = int(np.argmin(np.abs(frame_t - t)))
                    if k % args.every == 0 or err > args.above:
                        print('  frame %5d  position %7.2f cm  rotation %6.1f deg' % (frame, 100 * err, angle))
    return 0


# ----------------------------------------------------------------------------- self-test

def failed_targets(results):
    """(failed, scored): the object targets of a `report --json` result that
    failed and all that were scored (movers never visible score none)."""
    failed = scored = 0
    for res in results.values():
        for o in res.get('objects') or []:
            for v in (o.get('pass') or {}).values():
                scored += v is not None
                failed += v is False
    return failed, scored


def flatten_results(results):
    """Every number of a `report --json` result by a readable key: 'seq camera_ate',
    'seq object ate', ...; run times ('seconds') left out."""
    out = {}

    def walk(x, key):
        if isinstance(x, dict):
            for k, v in x.items():
                if k != 'seconds':
                    walk(v, key + (str(k),))
        elif isinstance(x, list):
            named = all(isinstance(v, dict) and 'name' in v for v in x)
            for i, v in enumerate(x):
                walk(v, key[:-1] + (v['name'],) if named else key + (str(i),))
        else:
            out[' '.join(key)] = x
    for seq, res in results.items():
        walk(res, (seq,))
    return out


def differences(a, b):
    """(key, value in a, value in b) for every number that differs between two
    `report --json` results, in key order; missing on one side is None."""
    fa, fb = flatten_results(a), flatten_results(b)
    return [(k, fa.get(k), fb.get(k)) for k in sorted(set(fa) | set(fb)) if fa.get(k) != fb.get(k)]


def compare(paths):
    """Prints the failed targets of two `report --json` files and every number that differs."""
    if len(paths) != 2:
        raise SystemExit('compare takes two files written by report --json (got %d)' % len(paths))
    results = []
    for p in paths:
        try:
            with open(p) as f:
                results.append(json.load(f))
        except (OSError, ValueError) as e:
            raise SystemExit('compare: cannot read %s: %s' % (p, e))
        if not isinstance(results[-1], dict):
            raise SystemExit('compare: %s is not a report --json file (no sequences)' % p)
    for p, r in zip(paths, results):
        print('%s: %d of %d object targets failed, %d sequences' % (p, *failed_targets(r), len(r)))
    diff = differences(*results)
    small = 0
    for k, x, y in diff:
        cm = k.endswith('ate') and all(isinstance(v, (int, float)) for v in (x, y))
        x, y = ('%.2f cm' % (100 * x), '%.2f cm' % (100 * y)) if cm else (x, y)
        if cm and x == y:
            small += 1  # an ATE that moved by less than the printed 0.01 cm
            continue
        print('  %-60s %s -> %s' % (k, x, y))
    print('%d numbers differ (%d of them ATEs by less than 0.01 cm, not listed)' % (len(diff), small))
    return 0


def selftest_movers_removed(np):
    """write_movers_removed on a two-frame sequence folder (skipped without cv2): the depth of the
    movers' pixels removed, every other entry linked; a missing mask named."""
    try:
        import cv2
    except ImportError:
        print('selftest: no cv2, write_movers_removed not checked')
        return
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        seq = os.path.join(tmp, 'seq')
        for d in ('depth', 'masks_gt', 'rgb'):
            os.makedirs(os.path.join(seq, d))
        with open(os.path.join(seq, 'depth.txt'), 'w') as f:
            f.write('0.0 depth/000000.png\n0.033 depth/000001.png\n')
        depth = np.full((6, 8), 7000, np.uint16)
        labels = np.zeros((6, 8), np.uint8)
        labels[2:4, 3:6] = 1
        for fn in ('000000.png', '000001.png'):
            cv2.imwrite(os.path.join(seq, 'depth', fn), depth)
            cv2.imwrite(os.path.join(seq, 'masks_gt', fn), labels)
        out = os.path.join(tmp, 'out')
        write_movers_removed(seq, out)
        written = cv2.imread(os.path.join(out, 'depth', '000001.png'), cv2.IMREAD_UNCHANGED)
        assert written.dtype == np.uint16 and (written == remove_movers(depth, labels)).all()
        assert os.path.islink(os.path.join(out, 'depth.txt')) and os.path.islink(os.path.join(out, 'rgb'))
        assert not os.path.islink(os.path.join(out, 'depth'))
        assert (cv2.imread(os.path.join(seq, 'depth', '000001.png'), cv2.IMREAD_UNCHANGED) == depth).all()
        os.remove(os.path.join(seq, 'masks_gt', '000001.png'))
        try:
            write_movers_removed(seq, os.path.join(tmp, 'out2'))
            raise AssertionError('write_movers_removed went on without a mask')
        except SystemExit as e:
            assert os.path.join('masks_gt', '000001.png') in str(e), str(e)
        # in a run, that fails the one reference (its copy removed), not the whole run
        comp = C('x', '0:2', 1, 'cup:mug')
        work = os.path.join(tmp, 'work')
        os.makedirs(os.path.dirname(seq_dir(work, comp)))
        os.rename(seq, seq_dir(work, comp))
        args = argparse.Namespace(work=work, backend='cpu', tag='', track_camera='/bin/true')
        path = movers_removed_path(work, comp, 'cpu')
        name, status, _ = run_movers_removed(args, comp, path)
        assert status.startswith('failed') and '000001.png' in status, status
        assert not os.path.exists(path + '.seq') and not os.path.exists(path)


def selftest():
    """Checks of the metric code on small constructed cases (77, skipped, without numpy)."""
    try:
        import numpy as np
    except ImportError:
        print('selftest skipped: %s has no numpy (Debian: apt-get install python3-numpy)' % sys.executable)
        return 77
    # visibility rule: a 40x40 block inside the border counts; moved partly into the border not
    lab = np.zeros((120, 160), np.uint8)
    lab[30:70, 40:80] = 1
    assert inner_area(lab, 1) == 1600
    lab2 = np.zeros((120, 160), np.uint8)
    lab2[10:50, 40:80] = 2       # 10 of its 40 rows in the top border
    assert inner_area(lab2, 2) == 1200 and int((lab2 == 2).sum()) == 1600
    lab3 = np.zeros((120, 160), np.uint8)
    lab3[20:60, 20:60] = 3       # touches the border from inside: all counted
    assert inner_area(lab3, 3) == 1600
    # the composites' camera reference: track_camera on frames 0:N of the base, shared by
    # composites on the same frames; none for a range that does not start at 0 or a synthetic room
    comp = C('x', '0:300', 1, 'cup:mug')
    assert reference_frames(comp) == 300 and reference_frames(C('x', '255:345', 1, 'cup:mug')) is None
    assert reference_frames(S('x', 300, 1, 'cup:mug')) is None
    assert reference_path('/w', comp, 'cpu-t') == os.path.join('/w', 'runs', 'cpu-t', 'track_camera',
                                                             'redkitchen_300-300.txt')
    assert reference_path('/w', C('y', '0:300', 2, 'car:toy_car'), 'cpu') == reference_path('/w', comp, 'cpu')
    # ... and track_camera on each composite without its movers' pixels: one per composite
    assert movers_removed_path('/w', comp, 'cpu') == os.path.join('/w', 'runs', 'cpu', 'track_camera',
                                                                   'x-movers-removed.txt')
    assert movers_removed_path('/w', S('x', 300, 1, 'cup:mug'), 'cpu') is None
    depth = np.arange(1, 13, dtype=np.uint16).reshape(3, 4) * 1000
    labels = np.zeros((3, 4), np.uint8)
    labels[1, 1:3], labels[2, 3] = 1, 2
    kept = remove_movers(depth, labels)
    assert (kept[labels > 0] == 0).all() and (kept[labels == 0] == depth[labels == 0]).all()
    assert depth[1, 1] == 6000 and kept.dtype == np.uint16  # the input is left as it was
    try:
        remove_movers(depth, labels[:2])
        raise AssertionError('remove_movers took labels of another size')
    except ValueError:
        pass
    selftest_movers_removed(np)
    # the info line: a failed camera reference that track_camera without the movers shares
    cam = dict(kind='composite', cam_ref_pass=False, camera_ate=0.0258, cam_reference=0.0225)
    results = {'shared': dict(cam, cam_movers_removed=0.0262), 'margin': dict(cam, cam_movers_removed=0.0250),
               'worse': dict(cam, cam_movers_removed=0.0245), 'unknown': dict(cam, cam_movers_removed=None),
               'passes': dict(cam, cam_ref_pass=True, cam_movers_removed=0.0262)}
    assert [name for name, _ in hidden_background(results)] == ['shared', 'margin']
    # detections: an instance is object k when half its pixels are on k
    det = np.zeros((120, 160), np.uint8)
    det[30:70, 40:60] = 5        # on object 1
    det[90:110, 100:150] = 7     # nowhere: a false positive
    assert detected_labels(det, lab, [5, 7, 9]) == [1]

    # a sequence of 12 frames, detector every 3 frames; object 1 visible (inner area 1600) from
    # frame 2 on except frames 8-9 (only 1599 inner pixels, still seen by the 1-pixel rule)
    fr = []
    for f in range(12):
        inner = 1600 if f >= 2 and f not in (8, 9) else (1599 if f in (8, 9) else 0)
        d = dict(t='%.6f' % (f / 30), area=[inner + 5 if inner else 0], inner=[inner])
        if f % 3 == 0:
            d['detected'] = [1] if f not in (3,) else []    # missed at frame 3
        fr.append(d)
    labels = dict(frames=fr, objects=['a'], det_every=3)
    ft = np.array([f / 30 for f in range(12)])
    assert visible_frames(labels, 1) == [2, 3, 4, 5, 6, 7, 10, 11]
    # one estimate from frame 6 (created after the missed frame 3: allowed 3 * (1 + 1) = 6)
    m = object_metrics('a', 1, labels, ft, 30.0, 3, {4: set(range(6, 12))}, 'synthetic')
    assert m['first_visible'] == 2 and m['created'] == 6 and m['creation_delay'] == 4
    assert m['missed_detections'] == 1 and m['creation_allowed'] == 6
    assert m['fragments'] == 1 and m['duplicate_frames'] == 0 and m['lost_frames'] == 0
    assert abs(m['coverage'] - 4 / 8) < 1e-12 and m['visible'] == 8 and m['visible_any'] == 10
    assert m['coverage_from_creation'] == 1.0  # visible 6, 7, 10, 11 from its creation at 6: all covered
    # the same object created at 6 but tracked back to 3 (run.json's creation): the delay counts
    # from the creation, the coverage every frame with a pose
    m = object_metrics('a', 1, labels, ft, 30.0, 3, {4: set(range(3, 12))}, 'synthetic', {4: 6})
    assert m['created'] == 6 and m['creation_delay'] == 4 and abs(m['coverage'] - 7 / 8) < 1e-12
    j = judge_object(dict(m, ate=0.004), 'synthetic')
    assert j == dict(lost=True, dup=True, create=True, obj_ate=True, coverage=False), j
    # two fragments, overlapping at frames 5-6 (duplicates), a gap 7,10 of which 7 and 10-11 are
    # visible: runs 7 (1 frame; 8-9 are not visible and end the run) and 10-11 (2 frames)
    m = object_metrics('a', 1, labels, ft, 30.0, 3, {1: {2, 3, 4, 5, 6}, 2: {5, 6}}, 'synthetic')
    assert m['fragments'] == 2 and m['duplicate_frames'] == 2 and m['lost_frames'] == 2
    assert m['creation_delay'] == 0 and m['missed_detections'] == 0
    assert abs(m['coverage_from_creation'] - 5 / 8) < 1e-12  # created at once: the same as coverage
    j = judge_object(dict(m, ate=0.015), 'composite')
    assert j['dup'] is False and j['obj_ate'] is True and j['lost'] is True
    # never created: creation and lost fail, coverage 0
    m = object_metrics('a', 1, labels, ft, 30.0, 3, {}, 'synthetic')
    assert m['created'] is None and m['missed_detections'] == 1 and m['coverage'] == 0
    j = judge_object(dict(m, ate=None), 'synthetic')
    assert not any(j.values())
    # lost longer than 1 s at 30 fps: visible 0-99, estimate 0-9 and 50-99: 40 frames = 1.33 s
    fr = [dict(t='%.6f' % (f / 30), area=[2000], inner=[2000]) for f in range(100)]
    labels = dict(frames=fr, objects=['a'], det_every=30)
    m = object_metrics('a', 1, labels, np.arange(100) / 30, 30.0, 30,
                       {1: set(range(10)), 2: set(range(50, 100))}, 'synthetic')
    assert m['lost_frames'] == 40 and abs(m['lost_s'] - 40 / 30) < 1e-12 and m['fragments'] == 2
    assert judge_object(dict(m, ate=0.001), 'synthetic')['lost'] is False

    # association, alignment, ATE and object ATE: an estimate in another world frame and another
    # object frame gives 0; a known offset gives its RMSE
    assert associate([0.0, 0.01, 0.1], [0.005, 0.1, 0.2]) == [(0, 0), (2, 1)]
    rng = np.random.default_rng(1)

    def rot(axis, ang):
        a = np.asarray(axis, float) / np.linalg.norm(axis)
        K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
        return np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K

    def pose(R, t):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
        return T

    n = 20
    t = np.arange(n) / 30.0
    gc = np.stack([pose(rot([0, 1, 0.2], 0.05 * i), [0.02 * i, 0.01 * i * i / 20, 0.1]) for i in range(n)])
    go = np.stack([pose(rot([0, 0, 1], 0.1 * i), [1 + 0.03 * i, 0.5, 0.02 * i]) for i in range(n)])
    W = pose(rot([1, 2, 3], 0.7), [3, -1, 2])             # estimate's world frame
    O = pose(rot([0.3, 1, 0], 0.4), [0.05, -0.02, 0.1])   # estimate's object frame
    ec = np.einsum('ij,njk->nik', np.linalg.inv(W), gc)
    eo = np.einsum('ij,njk,kl->nil', np.linalg.inv(W), go, O)
    assert camera_ate((t, ec), (t, gc)) < 1e-9
    a, k = object_ate((t, ec), (t, gc), (t, eo), (t, go))
    assert a < 1e-9 and k == n
    # a 2 cm error along the world's x at every other frame (not the first, which sets the
    # offset): the best fit splits it, +-1 cm (a rotation can take off a little)
    eo2 = eo.copy()
    eo2[1::2, :3, 3] += np.linalg.inv(W)[:3, :3] @ [0.02, 0, 0]
    a, _ = object_ate((t, ec), (t, gc), (t, eo2), (t, go))
    assert 0.009 < a <= 0.01 + 1e-12, a
    # a camera that drifts 1 cm a frame along x, and an object seen exactly relative to it: the
    # world-frame ATE grows with the drift, through the true camera it is 0
    D = np.stack([pose(np.eye(3), [0.01 * i, 0, 0]) for i in range(n)])
    ecd = np.einsum('nij,njk->nik', D, ec)
    eod = np.einsum('nij,njk->nik', D, eo)
    assert object_ate((t, ecd), (t, gc), (t, eod), (t, go))[0] > 0.01
    tt, et = through_true_camera((t, ecd), (t, gc), (t, eod))
    assert len(tt) == n and object_ate((t, gc), (t, gc), (tt, et), (t, go))[0] < 1e-9
    # per-frame errors: none for the exact estimate; for eo2, 2 cm at the odd frames, in the
    # camera frame, and no turn
    rows = frame_errors((t, ec), (t, gc), (t, eo), (t, go))
    assert len(rows) == n and max(r[1] for r in rows) < 1e-9 and max(r[2] for r in rows) < 1e-4, rows
    rows = frame_errors((t, ec), (t, gc), (t, eo2), (t, go))
    assert [abs(r[1] - (0.02 if i % 2 else 0)) < 1e-9 for i, r in enumerate(rows)] == [True] * n, rows
    assert max(r[2] for r in rows) < 1e-4
    # an estimate turned by 10 degrees from frame 10 on, about its own origin
    eo3 = eo.copy()
    eo3[10:] = np.einsum('nij,jk->nik', eo[10:], pose(rot([0, 0, 1], np.radians(10)), [0, 0, 0]))
    rows = frame_errors((t, ec), (t, gc), (t, eo3), (t, go))
    assert all(abs(r[2] - (10 if i >= 10 else 0)) < 1e-3 for i, r in enumerate(rows)), rows
    # matching: the estimate goes to the nearer truth object, a far one to none
    go_far = go.copy()
    go_far[:, :3, 3] += [0.5, 0, 0]
    eo_far = np.einsum('ij,njk->nik', np.linalg.inv(W), go_far)
    eo_far[:, :3, 3] += [0, 2, 0]
    by, unmatched = match_objects((t, ec), (t, gc), {1: (t, eo), 2: (t[:2], eo[:2]), 3: (t, eo_far)},
                                  {'a': (t, go), 'b': (t, go_far)})
    assert by == {'a': [1], 'b': []} and unmatched == [2, 3], (by, unmatched)
    # merged ids from run.json: only objects with a "merged" event; no file, none
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, 'run.json')
        assert merged_ids(p) == set()
        with open(p, 'w') as f:
            json.dump({'objects': [{'id': 1, 'events': [{'event': 'absorbed', 'from': 4}]},
                                   {'id': 4, 'events': [{'event': 'created', 'timestamp': 0.5},
                                                        {'event': 'merged', 'into': 1}]}]}, f)
        assert merged_ids(p) == {4}
        assert creation_times(p) == {4: 0.5}  # object 1's creation is not in this file
    # compare: targets counted per object; objects keyed by name, run times left out
    ra = {'s1': {'camera_ate': 0.001, 'seconds': 5.0, 'objects': [
        {'name': 'cup_1', 'ate': 0.002, 'pass': {'lost': True, 'obj_ate': True, 'coverage': None}}]}}
    rb = {'s1': {'camera_ate': 0.001, 'seconds': 9.0, 'objects': [
        {'name': 'cup_1', 'ate': 0.03, 'pass': {'lost': True, 'obj_ate': False, 'coverage': None}}]}}
    assert failed_targets(ra) == (0, 2) and failed_targets(rb) == (1, 2)
    assert differences(ra, rb) == [('s1 cup_1 ate', 0.002, 0.03),
                                   ('s1 cup_1 pass obj_ate', True, False)], differences(ra, rb)
    # compare's bad input: one clear message naming the file
    for bad, words in ((['/nonexistent/a.json', '/nonexistent/b.json'], '/nonexistent/a.json'),
                       (['only-one.json'], 'two files')):
        try:
            compare(bad)
            raise AssertionError('compare accepted %s' % bad)
        except SystemExit as e:
            assert words in str(e), e
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, 'list.json')
        with open(p, 'w') as f:
            json.dump([1, 2], f)
        try:
            compare([p, p])
            raise AssertionError('compare accepted a list')
        except SystemExit as e:
            assert p in str(e) and 'not a report' in str(e), e
    # a built-in scene: its own cache key, its export command, and its scene.json read as the
    # generator's dyngen.json (the objects in label order, the detector's period)
    room = B('r', 'synthetic:room', 300)
    assert seq_params(room) == dict(kind='synthetic', scene='synthetic:room', frames=300)
    assert seq_dir('/w', room) != seq_dir('/w', B('r', 'synthetic:corridor', 300))
    assert export_command('/app', room, '/out') == ['/app', 'export', 'synthetic:room', '/out',
                                                    '--max-frames', '300']
    with tempfile.TemporaryDirectory() as d:
        try:
            sequence_info(d)
            raise AssertionError('sequence_info read an empty folder')
        except SystemExit as e:
            assert d in str(e) and 'scene.json' in str(e), e
        with open(os.path.join(d, 'scene.json'), 'w') as f:
            f.write('{"objects": [{"name": "car_1"}], "det_')
        try:
            sequence_info(d)
            raise AssertionError('sequence_info read a cut file')
        except SystemExit as e:
            assert os.path.join(d, 'scene.json') in str(e) and 'not valid JSON' in str(e), e
        with open(os.path.join(d, 'scene.json'), 'w') as f:
            json.dump(dict(objects=[dict(name='car_1'), dict(name='cup_2')], det_every=30), f)
        info = sequence_info(d)
        assert [o['name'] for o in info['objects']] == ['car_1', 'cup_2'] and info['det_every'] == 30
    print('selftest: all checks passed')
    return 0


# ----------------------------------------------------------------------------- main

def main():
    if len(sys.argv) == 3 and sys.argv[1] == '_labels':   # internal: labels_summary through /usr/bin/python3
        write_labels_summary(sys.argv[2])
        return 0
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('step', choices=['list', 'generate', 'export', 'run', 'report', 'all', 'errors', 'selftest',
                                     'compare'])
    ap.add_argument('files', nargs='*', help='compare: two files written by report --json')
    ap.add_argument('--work', default=os.path.join(HERE, 'out'),
                    help='folder for sequences and runs (default bench/out, git-ignored)')
    ap.add_argument('--app', default=os.path.join(REPO, 'build', 'examples', 'emfusion'),
                    help='the emfusion app (default build/examples/emfusion)')
    ap.add_argument('--track-camera', default=os.path.join(REPO, 'build', 'examples', 'track_camera'),
                    help="track_camera, the composites' camera reference (default build/examples/track_camera)")
    ap.add_argument('--backend', default='cpu', choices=['cpu', 'cuda'])
    ap.add_argument('--jobs', type=int, default=1, help='app runs in parallel (default 1)')
    ap.add_argument('--gen-jobs', type=int, default=min(os.cpu_count() or 1, 16),
                    help="processes for the generator's rendering (default: the cores, at most 16)")
    ap.add_argument('--only', default=None, help='comma-separated sequence names (of the full, quick or a held-out list)')
    ap.add_argument('--quick', action='store_true', help='the three short validation sequences only')
    ap.add_argument('--holdout', action='store_true',
                    help='the held-out sequences (HOLDOUT: never tuned on) instead of the main list')
    ap.add_argument('--fresh', action='store_true',
                    help='the second held-out set (FRESH, made in the forty-fifth session) instead of the main list')
    ap.add_argument('--to', default=None, help='export: the folder to copy the sequences to')
    ap.add_argument('--markdown', action='store_true', help='print the table as markdown')
    ap.add_argument('--json', default=None, help='also write the scored results to this file')
    ap.add_argument('--every', type=int, default=10, help='errors: print every n-th frame (default 10)')
    ap.add_argument('--above', type=float, default=0.05,
                    help='errors: and every frame whose position error exceeds this, metres (default 0.05)')
    ap.add_argument('--tag', default='', help='run and report: a name for this set of runs (runs/<backend><tag>/), '
                    'so that runs with other --app-arg settings sit side by side, e.g. --tag=-predict')
    ap.add_argument('--app-arg', dest='app_args', action='append', default=[],
                    help='extra argument for `emfusion run` (repeatable, e.g. --app-arg=--set --app-arg=key=value)')
    args = ap.parse_args()
    if args.every < 1:
        ap.error('--every must be at least 1 (got %d)' % args.every)
    args.work = os.path.abspath(args.work)
    args.app = os.path.abspath(args.app)
    args.track_camera = os.path.abspath(args.track_camera)

    if args.step == 'selftest':
        return selftest()
    if args.step == 'compare':
        return compare(args.files)
    seqs = QUICK if args.quick else HOLDOUT if args.holdout else FRESH if args.fresh else SEQUENCES
    if args.only:
        want = args.only.split(',')
        known = {s['name']: s for s in SEQUENCES + QUICK + HOLDOUT + FRESH}
        missing = [w for w in want if w not in known]
        if missing:
            raise SystemExit('unknown sequence(s): %s (see the list step)' % ', '.join(missing))
        seqs = [known[w] for w in want]
    if args.step == 'list':
        for s in seqs:
            d = seq_dir(args.work, s)
            state = 'generated' if os.path.isfile(os.path.join(d, 'bench_labels.json')) else 'missing'
            runs = [b for b in ('cpu', 'cuda') if os.path.isfile(os.path.join(run_dir(args.work, s, b), 'bench_run.json'))]
            print('%-20s %-9s %-9s runs: %-8s %s' % (s['name'], s['kind'], state, ','.join(runs) or '-', ' '.join(
                shlex.quote(c) for c in generation_command(args, s, d))))
        return 0
    if args.step in ('generate', 'all'):
        generate(args, seqs)
    if args.step == 'export':
        export(args, seqs)
    if args.step in ('run', 'all'):
        run(args, seqs)
    if args.step == 'errors':
        return errors(args, seqs)
    if args.step in ('report', 'all'):
        return report(args, seqs)
    return 0


if __name__ == '__main__':
    sys.exit(main())
