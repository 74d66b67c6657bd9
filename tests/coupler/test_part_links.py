"""The links between a coupler on several ranks and a participant's ranks (docs/protocol.md,
"Parts"): every coupler rank is a peer listening on its own endpoint, rank 0 of a participant
links to every coupler rank, rank r to coupler rank 0 and rank r mod P. A peer routes nothing:
each exchange goes straight between the two processes that make it, and a coupler rank sees the
liveliness tokens it watches (the participant's, from its rank 0) without coupler rank 0."""

from __future__ import annotations

import time
import uuid

from coupler.fsi.held import assigned
from coupler.protocol.transport import (alive_key, coupler_rank_of, open_listening_session, open_session,
                                        part_key, part_links)


def test_each_participant_rank_links_to_the_coupler_ranks_it_talks_to():
    E = ["tcp/127.0.0.1:1001", "tcp/127.0.0.1:1002", "tcp/127.0.0.1:1003"]
    assert part_links(E, 0) == E
    assert [part_links(E, r) for r in (1, 2, 3, 4)] == [[E[0], E[1]], [E[0], E[2]], [E[0]], [E[0], E[1]]]
    assert part_links([], 3) == [] and part_links(E[:1], 5) == E[:1]
    for P, parts in ((1, 3), (2, 5), (3, 2), (4, 9)):  # the coupler holds the parts of the ranks linked to it
        for r in range(parts):
            assert r in assigned(coupler_rank_of(r, P), P, parts)
        assert sorted(sum((assigned(k, P, parts) for k in range(P)), [])) == list(range(parts))


def test_a_coupler_rank_reaches_its_participant_ranks_without_rank_0():
    """Coupler ranks 0 and 1 (peers), a participant on 3 ranks linked by part_links: coupler rank 1
    cannot reach participant rank 2 (coupler rank 0's: rank 0 routes nothing), and gets the parts of
    participant ranks 1 and 0 and sees the participant's token after coupler rank 0's session is
    closed."""
    run = f"links-{uuid.uuid4().hex[:8]}"
    sessions = [open_listening_session("127.0.0.1", mode="peer") for _ in range(2)]
    endpoints = [e for _, e in sessions]
    parts = [open_session("peer", part_links(endpoints, r)) for r in range(3)]
    try:
        queryables = [s.declare_queryable(part_key(run, "solid", "advance", r),
                                          lambda q, r=r: q.reply(q.key_expr, f"part {r}".encode()))
                      for r, s in enumerate(parts)]
        token = parts[0].liveliness().declare_token(alive_key(run, "solid"))
        time.sleep(0.3)
        rank1 = sessions[1][0]

        def ask(r):
            return [bytes(reply.ok.payload.to_bytes()) for reply in
                    rank1.get(part_key(run, "solid", "advance", r), timeout=2.0) if reply.ok is not None]

        assert ask(2) == []  # linked to coupler rank 0 only, which routes nothing
        sessions[0][0].close()
        time.sleep(0.3)
        assert ask(1) == [b"part 1"]
        assert ask(0) == [b"part 0"]  # participant rank 0 links to every coupler rank
        alive = [str(r.ok.key_expr) for r in rank1.liveliness().get(alive_key(run, "solid"), timeout=2.0)]
        assert alive == [alive_key(run, "solid")]
        token.undeclare()
        del queryables
    finally:
        for s in parts + [sessions[1][0]]:
            s.close()
