"""``python -m grasp_tools.hands --count N --seed S --out DIR``: random hands and a campaign.

Writes ``DIR/hand_NNN/hand.urdf`` and ``DIR/hand_NNN/scenario.yaml`` for hands 0..N-1,
``DIR/hands.csv`` (one row per hand) and ``DIR/campaign.yaml`` (every scenario, both modes,
a gentle random reference each), and prints how many draws were refused and why. Hand i is
drawn from ``numpy.random.default_rng([S, i])``: more hands keep the earlier ones.
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path
import sys

from grasp_tools.hands.campaign import CAMPAIGN_NAME, INDEX_NAME, write_campaign, write_index
from grasp_tools.hands.grasp import generate_hand

PROG = 'python -m grasp_tools.hands'


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split('\n\n')[0])
    parser.add_argument('--count', type=int, required=True, help='number of hands')
    parser.add_argument('--seed', type=int, default=0, help='seed (default 0)')
    parser.add_argument('--out', type=Path, required=True, help='output directory')
    parser.add_argument(
        '--duration', type=float, default=5.0, help='campaign run duration, s (default 5)'
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Generate the hands, their index and campaign; return the exit status."""
    args = _parser().parse_args(argv)
    if args.count < 1 or args.seed < 0 or args.duration <= 0:
        print(f'{PROG}: --count >= 1, --seed >= 0 and --duration > 0 expected', file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    rows, refused = [], Counter()
    for index in range(args.count):
        hand = generate_hand(args.seed, index, args.out / f'hand_{index:03d}')
        row = hand.row()
        rows.append(row)
        refused.update(hand.rejections)
        print(
            f'hand {index:03d}: {row["fingers"]} fingers, {row["joints"]} joints, '
            f'{row["object"]}, {row["rejected"]} draws refused'
            + (f' ({row["rejections"]})' if row['rejections'] else '')
        )
    write_index(args.out / INDEX_NAME, rows)
    write_campaign(
        args.out / CAMPAIGN_NAME, [row['scenario'] for row in rows], args.seed, args.duration
    )
    total = sum(refused.values())
    reasons = ', '.join(f'{reason} {count}' for reason, count in refused.most_common()) or '—'
    print(
        f'{PROG}: {args.count} hands in {args.out}; {total} draws refused of '
        f'{total + args.count} ({100 * total / (total + args.count):.0f} %): {reasons}'
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
