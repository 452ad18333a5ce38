"""Fuzz the rosbridge protocol layer for a long time and print how much was tried.

The strategies and invariants are those of ``tests/test_fuzz_protocol.py`` (imported, not
copied): random JSON values, op-shaped dicts, text and bytes from a student and an admin client
into ``Bridge.handle``, a tick after each; nothing may raise, the robot keeps stepping with a
finite state, every outgoing frame is strict JSON or CBOR. It runs rounds of Hypothesis
generation (no shrinking, no example database) with a new seed each, until ``--messages``
frames were fed, and stops at the first failure, printing the failing frames and the seed.

Run it from the checkout::

    python benchmarks/fuzz_protocol.py --messages 100000
"""

from __future__ import annotations

import argparse
import logging
import random
import sys
import time
from pathlib import Path

from hypothesis import HealthCheck, Phase, given, seed, settings

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from test_fuzz_protocol import SESSIONS, run_session

EXAMPLES_PER_ROUND = 500
"""Sessions per Hypothesis round; each round has its own seed."""


def main(argv: list[str] | None = None) -> int:
    """Fuzz until ``--messages`` frames were handled; 0 when nothing failed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=100_000,
                        help="frames to feed in total (default 100000)")
    parser.add_argument("--seed", type=int, default=None,
                        help="first round's seed (default random); round k uses seed + k")
    args = parser.parse_args(argv)
    logging.disable(logging.WARNING)  # every refused frame is logged; here they are expected
    first_seed = random.randrange(2**32) if args.seed is None else args.seed
    counted = {"messages": 0, "sessions": 0}
    started = time.perf_counter()
    round_index = 0
    while counted["messages"] < args.messages:
        round_seed = first_seed + round_index

        @seed(round_seed)
        @settings(max_examples=EXAMPLES_PER_ROUND, deadline=None, database=None,
                  phases=[Phase.generate], suppress_health_check=list(HealthCheck))
        @given(SESSIONS)
        def fuzz(frames: list[tuple[bool, str | bytes]]) -> None:
            run_session(frames)
            counted["messages"] += len(frames)
            counted["sessions"] += 1

        try:
            fuzz()
        except Exception:
            print(f"fuzz_protocol: FAILED in round {round_index} (seed {round_seed}) after "
                  f"{counted['messages']} messages", file=sys.stderr)
            raise
        round_index += 1
        elapsed = time.perf_counter() - started
        print(f"  {counted['messages']:>8} messages, {counted['sessions']:>6} sessions, "
              f"{elapsed:7.1f} s", flush=True)
    elapsed = time.perf_counter() - started
    print(f"fuzz_protocol: {counted['messages']} messages in {counted['sessions']} sessions, "
          f"{round_index} rounds from seed {first_seed}, {elapsed:.1f} s "
          f"({counted['messages'] / elapsed:.0f} messages/s): no failure")
    return 0


if __name__ == "__main__":
    sys.exit(main())
