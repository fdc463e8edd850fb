#!/usr/bin/env python3
"""A 'there and back' base sequence for composites: a static TUM-layout sequence played
forward, backward, forward, ... (the turning frames are not repeated), for --frames frames.

Timestamps are re-stamped to increase at the base's mean frame period from the base's first
timestamp; every frame keeps the reference camera pose of the frame it shows. The output holds
rgb.txt, depth.txt, associations.txt, groundtruth.txt, calibration.txt and links `rgb` and
`depth` to the base's folders (no image is copied), so it carries the base's licence: keep it
in a git-ignored folder. It is a base for shared/tools/dyngen.py composite, e.g.

  /usr/bin/python3 bench/there_and_back.py --base ../shared/data/redkitchen_300 --frames 600 --out bench/out/base/tab600
  /usr/bin/python3 ../shared/tools/dyngen.py composite --base bench/out/base/tab600 --frames 0:600 --out DIR

--step K keeps every K-th frame of the played order (played frames 0, K, 2K, ... of the --frames
played): ceil(frames / K) frames, still re-stamped at the base's frame period, so the camera moves
K times as fast between frames (a frame-dropped recording). With the base's own length it is the
base with frames dropped:

  /usr/bin/python3 bench/there_and_back.py --base ../shared/data/redkitchen_300 --frames 300 --step 2 --out bench/out/seq/drop2
  /usr/bin/python3 bench/there_and_back.py --base ../shared/data/redkitchen_300 --frames 900 --step 2 --out bench/out/seq/tab900s2

K = 1 (the default) keeps every frame, the output as before the option existed. --frames and
--step must be positive integers, and must leave at least 2 frames.

Python 3 only (no numpy).
"""

import argparse
import os
import shutil
import sys


def read_list(path):
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith('#'):
                rows.append(line.split())
    return rows


def frame_order(n_base, n):
    """Base frame index of each output frame: 0..n_base-1, n_base-2..0, 1..n_base-1, ..."""
    if n_base < 2:
        return [0] * n
    period = 2 * (n_base - 1)
    out = []
    for i in range(n):
        k = i % period
        out.append(k if k < n_base else period - k)
    return out


def positive_int(name):
    """argparse type: an integer >= 1, else an error naming the option and the value."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError('%s expects a positive integer, got %r' % (name, text))
        if value < 1:
            raise argparse.ArgumentTypeError('%s expects a positive integer, got %r' % (name, text))
        return value
    return parse


def stepped(order, step):
    """Every step-th entry of the played order, from the first: a frame-dropped playback."""
    return order[::step]


def read_base_list(base, name, fields):
    """read_list of a file of the base with `fields` or more fields per row; SystemExit naming the file otherwise."""
    path = os.path.join(base, name)
    try:
        rows = read_list(path)
    except OSError as e:
        raise SystemExit('there_and_back: cannot read %s: %s (--base must be a TUM-layout sequence with '
                         'associations.txt and groundtruth.txt)' % (path, e.strerror or e))
    for i, r in enumerate(rows):
        if len(r) < fields:
            raise SystemExit('there_and_back: %s: data row %d has %d fields, expected %d' % (path, i + 1, len(r), fields))
    if not rows:
        raise SystemExit('there_and_back: %s has no data rows' % path)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--base', required=True, help='static TUM-layout sequence with associations.txt and groundtruth.txt')
    ap.add_argument('--frames', type=positive_int('--frames'), required=True,
                    help='frames played (forward, back, forward, ...) before --step')
    ap.add_argument('--step', type=positive_int('--step'), default=1,
                    help='keep every K-th played frame (default 1: all); the output has ceil(frames / K) frames')
    ap.add_argument('--out', required=True)
    args = ap.parse_args()
    kept = (args.frames + args.step - 1) // args.step
    if kept < 2:
        ap.error('--frames %d with --step %d keeps %d frame; a sequence needs at least 2 (use a smaller --step)'
                 % (args.frames, args.step, kept))
    base = os.path.abspath(args.base)
    if not os.path.isdir(base):
        raise SystemExit('there_and_back: --base %s is not a directory' % base)
    assoc = read_base_list(base, 'associations.txt', 4)
    gt = {r[0]: r[1:8] for r in read_base_list(base, 'groundtruth.txt', 8)}
    gt_t = sorted(gt, key=float)

    def pose_of(t):   # the reference pose at (or nearest, within 1 ms) the depth timestamp
        best = min(gt_t, key=lambda s: abs(float(s) - float(t)))
        if abs(float(best) - float(t)) > 1e-3:
            raise SystemExit('no reference pose at t=%s in %s' % (t, base))
        return gt[best]

    ts = [float(r[0]) for r in assoc]
    dt = (ts[-1] - ts[0]) / (len(ts) - 1) if len(ts) > 1 else 1 / 30.0   # mean period (stamps are rounded)
    order = stepped(frame_order(len(assoc), args.frames), args.step)
    os.makedirs(args.out, exist_ok=True)
    for d in ('rgb', 'depth'):
        link = os.path.join(args.out, d)
        if os.path.islink(link) or os.path.exists(link):
            os.remove(link) if os.path.islink(link) else shutil.rmtree(link)
        os.symlink(os.path.join(base, d), link)
    rows = []
    for i, k in enumerate(order):
        t = '%.6f' % (ts[0] + i * dt)
        rows.append((t, assoc[k][1], assoc[k][3], pose_of(assoc[k][2]), k))
    with open(os.path.join(args.out, 'associations.txt'), 'w') as f:
        f.writelines('%s %s %s %s\n' % (t, rgb, t, dep) for t, rgb, dep, _, _ in rows)
    with open(os.path.join(args.out, 'rgb.txt'), 'w') as f:
        f.write('# timestamp filename\n')
        f.writelines('%s %s\n' % (t, rgb) for t, rgb, _, _, _ in rows)
    with open(os.path.join(args.out, 'depth.txt'), 'w') as f:
        f.write('# timestamp filename\n')
        f.writelines('%s %s\n' % (t, dep) for t, _, dep, _, _ in rows)
    with open(os.path.join(args.out, 'groundtruth.txt'), 'w') as f:
        f.write('# camera-to-world, timestamp tx ty tz qx qy qz qw (reference poses of %s, re-stamped)\n' % base)
        f.writelines('%s %s\n' % (t, ' '.join(p)) for t, _, _, p, _ in rows)
    if os.path.isfile(os.path.join(base, 'calibration.txt')):
        shutil.copyfile(os.path.join(base, 'calibration.txt'), os.path.join(args.out, 'calibration.txt'))
    with open(os.path.join(args.out, 'README.txt'), 'w') as f:
        f.write('There-and-back sequence made by bench/there_and_back.py: %s played forward, backward, forward, ...\n'
                'for %d frames%s (base frames in order: %s), timestamps re-stamped every %.6f s,\n'
                'reference poses kept. Images are links into the base: its licence applies; do not commit.\n'
                % (base, args.frames, ', one in %d kept: %d frames' % (args.step, len(rows)) if args.step > 1 else '',
                   ' '.join(str(k) for _, _, _, _, k in rows), dt))
    print('there_and_back: %d frames of %s%s -> %s' % (args.frames, base,
                                                     ' (one in %d: %d frames)' % (args.step, len(rows))
                                                     if args.step > 1 else '', args.out))
    return 0


if __name__ == '__main__':
    sys.exit(main())
