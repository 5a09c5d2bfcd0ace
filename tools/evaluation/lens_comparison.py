#!/usr/bin/env python3
"""Loops through a known lens against the originals' (issue 65's camera-model check).

Each real set (the five Strecha keyframe walks, keyframes preset, with --poses; the corridor,
default preset, with an assumed K of 400 px since it has no calibration) is run three more ways:
  - through a known equidistant and a known radial-tangential lens: `recog seqgen lens` writes
    the images as that lens would have taken them (PNG), and `recog eval place --camera LENS:...`
    runs on them;
  - as a control without any lens: the same images magnified by the pinhole of the equidistant
    lens's focal length, which changes the features as much as a lens does, and no more.
Prints per set and lens: loops right and false, the loops found on both, and how far their
estimated relative rotations differ from the original's.

  tools/evaluation/lens_comparison.py [OUT_DIR]     (default /tmp/recog_lens_comparison)

Environment: RECOG (the recog binary, default the checkout's build/bin/recog), RECOG_SHARED_DATA
(default ../shared/data).
"""
import json
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
RECOG = os.environ.get('RECOG', os.path.join(HERE, '..', '..', 'build', 'bin', 'recog'))
DATA = os.environ.get('RECOG_SHARED_DATA', '../shared/data')
OUT = sys.argv[1] if len(sys.argv) > 1 else '/tmp/recog_lens_comparison'


def strecha(scene):
    d = f'{DATA}/places/strecha-keyframes/{scene}'
    K = open(f'{d}/camera.txt').read().strip()
    cx, cy = K.split(',')[2:4]
    flags = ['--ground-truth', f'{d}/ground_truth.txt', '--ambiguous', f'{d}/ambiguous.txt',
             '--poses', f'{d}/poses.txt', '--preset', 'keyframes']
    # Focal lengths chosen so that the lens sees no further than the 1024x683 originals do.
    return (scene, f'{d}/images', K, flags, {
        'equidistant': f'equidistant:1050,1050,{cx},{cy},-0.01,0.005,0,0',
        'radtan': f'radtan:1000,1000,{cx},{cy},-0.15,0.03,0.0005,-0.0003,0',
        'control (pinhole, f 1050)': f'1050,1050,{cx},{cy}'})


CORRIDOR = f'{DATA}/places/corridor'
SETS = [strecha(s) for s in ['castle-P30', 'castle-P19', 'entry-P10', 'fountain-P11',
                             'Herz-Jesus-P8']]
SETS.append(('corridor', f'{CORRIDOR}/images', '400,400,255.5,191.5',
             ['--ground-truth', f'{CORRIDOR}/ground_truth.txt'], {
                 'equidistant': 'equidistant:480,480,255.5,191.5,-0.01,0.005,0,0',
                 'radtan': 'radtan:440,440,255.5,191.5,-0.15,0.03,0.0005,-0.0003,0',
                 'control (pinhole, f 480)': '480,480,255.5,191.5'}))


def evaluate(images, camera, flags):
    run = subprocess.run([RECOG, 'eval', 'place', '--images', images, '--camera', camera,
                          '--json', '-q'] + flags, capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(run.stderr)
    report = json.loads(run.stdout)
    loops = {(l['query'], l['match']): l for l in report['loops']
             if l['status'] == 'loop_detected'}
    return report['correct'], report['detections'] - report['correct'], loops


def rotation(loop):
    evidence = loop.get('evidence', {})
    return evidence['rotation_deg'] if evidence.get('calibrated') else None


def median(values):
    values = sorted(values)
    return values[len(values) // 2] if values else float('nan')


def main():
    totals = {}
    for name, images, K, flags, lenses in SETS:
        right, false, original = evaluate(images, K, flags)
        print(f'{name}: the original (--camera {K}): {right} right, {false} false')
        totals.setdefault('original', [0, 0])
        totals['original'][0] += right
        totals['original'][1] += false
        for label, camera in lenses.items():
            warped = os.path.join(OUT, name, label.split(' ')[0])
            shutil.rmtree(warped, ignore_errors=True)
            subprocess.run([RECOG, 'seqgen', 'lens', '--images', images, '-o', warped,
                            '--source-camera', K, '--camera', camera, '-q'], check=True,
                           capture_output=True)
            right, false, loops = evaluate(warped, camera, flags)
            common = [k for k in loops if k in original]
            differences = [abs(rotation(loops[k]) - rotation(original[k])) for k in common
                           if rotation(loops[k]) is not None and rotation(original[k]) is not None]
            print(f'  {label} ({camera}): {right} right, {false} false; {len(common)} of the '
                  f"original's {len(original)} loops found again, their rotations "
                  f'{median(differences):.2f} deg apart (median)')
            totals.setdefault(label.split(' ')[0], [0, 0])
            totals[label.split(' ')[0]][0] += right
            totals[label.split(' ')[0]][1] += false
    print('all sets, right/false: ' +
          ', '.join(f'{k} {v[0]}/{v[1]}' for k, v in totals.items()))


if __name__ == '__main__':
    main()
