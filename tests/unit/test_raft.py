"""Unit tests of the pure Raft core, driven through a synchronous in-memory network.

In the style of etcd-io/raft's raft_test.go: whole groups, a network that delivers every
message in order unless a test cuts links or filters messages, and assertions on roles, terms,
logs and what each node applied.
"""

from __future__ import annotations

import random
from collections.abc import Callable

import pytest

from mapapi.swarm.raft import RaftNode, RaftOptions
from mapapi.swarm.raft_types import (
    NONE,
    ConfChange,
    ConfChangeKind,
    Config,
    Entry,
    EntryKind,
    Message,
    MessageKind,
    NotLeader,
    PersistentState,
    ProposalRefused,
    ReadState,
    Role,
)
from tests.sim.simulator import Disk

M = MessageKind
ELECTION = 10


class Network:
    """Nodes wired by a lossless, ordered, synchronous network (etcd's `network`)."""

    def __init__(
        self,
        voters: int = 3,
        learners: tuple[int, ...] = (),
        options: RaftOptions | None = None,
    ) -> None:
        self.options = options or RaftOptions(election_tick=ELECTION)
        config = Config(frozenset(range(1, voters + 1)), frozenset(learners))
        self.nodes: dict[int, RaftNode] = {}
        self.disks: dict[int, Disk] = {}
        self.applied: dict[int, list[Entry]] = {}
        self.reads: dict[int, list[ReadState]] = {}
        self.cut: set[tuple[int, int]] = set()
        self.drop: Callable[[Message], bool] = lambda m: False
        self.sent: list[Message] = []
        for nid in sorted(config.members):
            self.add(nid, PersistentState.bootstrap(config))

    def add(self, nid: int, state: PersistentState | None = None) -> RaftNode:
        """Start a node from `state` (a fresh, empty one by default)."""
        self.disks[nid] = Disk(state)
        self.nodes[nid] = RaftNode(nid, self.disks[nid].state(), random.Random(nid), self.options)
        self.applied[nid], self.reads[nid] = [], []
        return self.nodes[nid]

    def restart(self, nid: int) -> RaftNode:
        """Crash a node and start it again from what it persisted."""
        state = self.disks[nid].state()
        node = self.nodes[nid] = RaftNode(nid, state, random.Random(nid), self.options)
        self.applied[nid] = [e for e in self.applied[nid] if e.index <= state.snapshot.index]
        return node

    def flush(self) -> None:
        """Drive every Ready and deliver every message until the group is quiet."""
        queue: list[Message] = []
        while True:
            for nid, node in self.nodes.items():
                if node.has_ready():
                    rd = node.ready()
                    self.disks[nid].save(rd)
                    queue.extend(rd.messages)
                    self.applied[nid].extend(rd.committed_entries)
                    self.reads[nid].extend(rd.read_states)
                    node.advance(rd)
            if not queue:
                return
            m = queue.pop(0)
            self.sent.append(m)
            if (m.sender, m.to) not in self.cut and not self.drop(m) and m.to in self.nodes:
                self.nodes[m.to].step(m)

    def isolate(self, nid: int) -> None:
        """Cut every link to and from `nid`."""
        for other in self.nodes:
            if other != nid:
                self.cut |= {(nid, other), (other, nid)}

    def heal(self) -> None:
        """Restore every link."""
        self.cut.clear()

    def tick(self, nid: int, n: int) -> None:
        """Tick one node `n` times, flushing after each."""
        for _ in range(n):
            self.nodes[nid].tick()
            self.flush()

    def tick_all(self, nids: tuple[int, ...], n: int) -> None:
        """Tick several nodes `n` times each, round robin, flushing after each round."""
        for _ in range(n):
            for nid in nids:
                self.nodes[nid].tick()
            self.flush()

    def elect(self, nid: int) -> RaftNode:
        """Make `nid` campaign; return it."""
        self.nodes[nid].campaign()
        self.flush()
        return self.nodes[nid]

    def propose(self, nid: int, *payloads: bytes) -> list[tuple[int, int]]:
        """Propose payloads at `nid` and flush."""
        out = [self.nodes[nid].propose(p) for p in payloads]
        self.flush()
        return out

    def data(self, nid: int) -> list[bytes]:
        """The normal entries `nid` applied."""
        return [e.data for e in self.applied[nid] if e.kind is EntryKind.NORMAL]


def roles(net: Network) -> dict[int, Role]:
    return {nid: node.role for nid, node in net.nodes.items()}


class TestElection:
    def test_a_campaign_elects_a_leader_that_all_follow(self) -> None:
        net = Network()
        leader = net.elect(1)
        assert roles(net) == {1: Role.LEADER, 2: Role.FOLLOWER, 3: Role.FOLLOWER}
        assert {n.term for n in net.nodes.values()} == {leader.term}
        assert all(n.leader == 1 for n in net.nodes.values())

    def test_election_timeout_elects_without_help(self) -> None:
        net = Network()
        net.tick(2, 2 * ELECTION)
        assert roles(net)[2] is Role.LEADER

    def test_a_single_voter_elects_itself(self) -> None:
        net = Network(voters=1)
        net.tick(1, 2 * ELECTION)
        assert net.nodes[1].role is Role.LEADER

    def test_no_majority_no_leader(self) -> None:
        net = Network()
        net.isolate(1)
        net.elect(1)
        assert net.nodes[1].role is Role.PRE_CANDIDATE

    def test_one_vote_per_term(self) -> None:
        net = Network(options=RaftOptions(election_tick=ELECTION, pre_vote=False))
        net.cut |= {(1, 3), (3, 1)}
        net.elect(1)  # node 2 votes for 1 in term 2
        net.nodes[3].campaign()  # term 2 too: 2 has voted already
        net.cut = {(1, 2), (2, 1), (1, 3), (3, 1)}
        net.flush()
        assert net.nodes[2].vote == 1
        assert net.nodes[3].role is Role.CANDIDATE

    def test_a_less_up_to_date_candidate_is_refused(self) -> None:
        net = Network()
        net.elect(1)
        net.isolate(3)
        net.propose(1, b"x")
        net.heal()
        net.isolate(1)
        net.tick_all((2, 3), 3 * ELECTION)  # 2 and 3 lose their lease
        net.elect(3)  # 3 lacks "x": 2 refuses
        assert net.nodes[3].role is not Role.LEADER
        net.elect(2)
        assert net.nodes[2].role is Role.LEADER


class TestPreVoteAndCheckQuorum:
    def test_partitioned_node_does_not_raise_its_term(self) -> None:
        net = Network()
        term = net.elect(1).term
        net.isolate(3)
        net.tick(3, 10 * ELECTION)
        assert net.nodes[3].term == term
        net.heal()
        net.tick(1, 2)
        assert net.nodes[1].role is Role.LEADER
        assert net.nodes[1].term == term

    def test_without_prevote_a_rejoining_node_deposes_the_leader(self) -> None:
        net = Network(options=RaftOptions(election_tick=ELECTION, pre_vote=False))
        term = net.elect(1).term
        net.isolate(3)
        net.tick(3, 10 * ELECTION)
        assert net.nodes[3].term > term
        net.heal()
        net.tick(1, 2)
        assert net.nodes[1].term > term

    def test_leader_cut_off_from_its_quorum_steps_down(self) -> None:
        net = Network()
        net.elect(1)
        net.isolate(1)
        net.tick(1, 2 * ELECTION + 1)
        assert net.nodes[1].role is Role.FOLLOWER

    def test_leader_with_quorum_stays(self) -> None:
        net = Network()
        net.elect(1)
        net.isolate(3)
        net.tick(1, 3 * ELECTION)
        assert net.nodes[1].role is Role.LEADER

    def test_followers_in_lease_ignore_a_candidate(self) -> None:
        net = Network(options=RaftOptions(election_tick=ELECTION, pre_vote=False))
        term = net.elect(1).term
        net.cut |= {(1, 3), (3, 1)}  # 3 stops hearing the leader; 2 still does
        net.tick(3, 3 * ELECTION)
        assert net.nodes[3].term > term  # 3 campaigned, without PreVote
        assert net.nodes[2].term == term  # 2 ignored it: it heard from 1 recently
        assert net.nodes[1].role is Role.LEADER

    def test_stale_leader_learns_the_new_term_from_an_append_response(self) -> None:
        net = Network()
        net.elect(1)
        net.isolate(1)
        net.tick_all((2, 3), 3 * ELECTION)
        assert net.nodes[2].role is Role.LEADER or net.nodes[3].role is Role.LEADER
        net.heal()
        net.nodes[1].propose(b"stale")
        net.flush()
        assert net.nodes[1].role is Role.FOLLOWER
        assert b"stale" not in net.data(2)


class TestReplication:
    def test_proposals_commit_and_apply_everywhere_in_order(self) -> None:
        net = Network()
        net.elect(1)
        net.propose(1, b"a", b"b", b"c")
        assert net.data(1) == net.data(2) == net.data(3) == [b"a", b"b", b"c"]

    def test_the_leader_names_the_voters_an_entry_waits_for(self) -> None:
        net = Network()
        net.elect(1)
        net.isolate(3)
        [(index, _)] = net.propose(1, b"x")
        assert net.nodes[1].lacking(index) == [3]  # committed by 1 and 2; 3 lacks it
        net.isolate(2)
        [(later, _)] = net.propose(1, b"y")
        assert net.nodes[1].lacking(later) == [2, 3]
        assert net.nodes[2].lacking(later) == []  # a follower names nobody

    def test_follower_refuses_a_proposal_naming_the_leader(self) -> None:
        net = Network()
        net.elect(1)
        with pytest.raises(NotLeader) as err:
            net.nodes[2].propose(b"x")
        assert err.value.leader == 1

    def test_conflicting_uncommitted_entries_are_replaced(self) -> None:
        net = Network()
        net.elect(1)
        net.propose(1, b"kept")
        net.isolate(1)
        net.propose(1, b"lost1", b"lost2")  # appended by 1 only
        net.tick_all((2, 3), 3 * ELECTION)
        new = next(n for n in (2, 3) if net.nodes[n].role is Role.LEADER)
        net.propose(new, b"won")
        net.heal()
        net.tick(new, 2)
        assert net.data(1) == net.data(2) == net.data(3) == [b"kept", b"won"]
        assert net.nodes[1].log.last_index == net.nodes[new].log.last_index

    def test_lagging_follower_catches_up_with_few_rejections(self) -> None:
        net = Network(options=RaftOptions(election_tick=ELECTION, max_entries_per_msg=4))
        net.elect(1)
        net.isolate(3)
        net.propose(1, *[b"%d" % i for i in range(40)])
        net.sent.clear()
        net.heal()
        net.tick(1, 1)
        rejections = [m for m in net.sent if m.kind is M.APP_RESP and m.reject]
        assert len(rejections) <= 1
        assert net.data(3) == net.data(1)

    def test_fast_backtracking_skips_a_divergent_term_at_once(self) -> None:
        net = Network()
        net.elect(1)
        net.isolate(1)
        net.propose(1, *[b"old%d" % i for i in range(30)])  # 30 entries nobody else has
        net.tick_all((2, 3), 3 * ELECTION)
        new = next(n for n in (2, 3) if net.nodes[n].role is Role.LEADER)
        net.heal()
        net.sent.clear()
        net.tick(new, 1)
        rejections = [m for m in net.sent if m.kind is M.APP_RESP and m.reject and m.sender == 1]
        assert len(rejections) <= 2
        assert net.data(1) == net.data(new)

    def test_leader_commits_an_old_term_entry_only_with_one_of_its_own(self) -> None:
        # Raft paper Fig. 8: counting replicas commits only entries of the current term.
        opts = RaftOptions(election_tick=ELECTION, max_entries_per_msg=1, check_quorum=False)
        net = Network(options=opts)
        net.elect(1)
        net.cut |= {(1, 3), (2, 1)}  # 2 gets the entry, 1 never hears it
        (old_index, old_term) = net.propose(1, b"old")[0]
        assert net.nodes[2].log.term(old_index) == old_term
        net.isolate(1)
        follower = net.nodes[3]
        net.drop = lambda m: (  # the no-op may not reach 3 once 3 holds "old"
            follower.log.last_index >= old_index
            and any(e.kind is EntryKind.NOOP for e in m.entries)
        )
        leader = net.elect(2)
        assert leader.role is Role.LEADER
        net.tick(2, 3)  # 3 receives "old" but not the new leader's no-op
        assert net.nodes[3].log.term(old_index) == old_term  # a majority holds "old"...
        assert leader.log.committed < old_index  # ...yet it is not committed
        net.drop = lambda m: False
        net.tick(2, 2)
        assert leader.log.committed > old_index
        assert net.data(3) == [b"old"]

    def test_restart_keeps_term_vote_and_log(self) -> None:
        net = Network()
        net.elect(1)
        net.propose(1, b"a")
        before = net.nodes[2]
        after = net.restart(2)
        assert (after.term, after.vote, after.log.last_index, after.log.committed) == (
            before.term,
            before.vote,
            before.log.last_index,
            before.log.committed,
        )

    def test_ready_must_be_advanced_before_the_next(self) -> None:
        net = Network()
        node = net.nodes[1]
        node.campaign()
        node.ready()
        with pytest.raises(RuntimeError, match="advance"):
            node.ready()

    def test_a_vote_is_persisted_in_the_ready_that_sends_it(self) -> None:
        net = Network(options=RaftOptions(election_tick=ELECTION, pre_vote=False))
        net.nodes[1].campaign()
        vote = next(m for m in net.nodes[1].ready().messages if m.to == 2)
        net.nodes[2].step(vote)
        rd = net.nodes[2].ready()
        granted = [m for m in rd.messages if m.kind is M.VOTE_RESP and not m.reject]
        assert granted
        assert rd.hard_state is not None
        assert rd.hard_state.vote == 1


class TestMembership:
    def test_learner_never_campaigns(self) -> None:
        net = Network(voters=1, learners=(2,))
        net.tick(2, 5 * ELECTION)
        assert net.nodes[2].role is Role.FOLLOWER
        assert net.nodes[2].term == 1

    def test_learner_receives_the_log_but_does_not_count_for_commit(self) -> None:
        net = Network(voters=2, learners=(3,))
        net.elect(1)
        net.isolate(2)
        net.propose(1, b"x")
        assert net.nodes[3].log.last_index == net.nodes[1].log.last_index
        assert b"x" not in net.data(1)  # 1 and the learner are not a majority of {1, 2}
        net.heal()
        net.tick(1, 1)
        assert net.data(1) == net.data(3) == [b"x"]

    def test_learner_vote_does_not_count(self) -> None:
        net = Network(voters=3, learners=(4,))
        net.cut |= {(1, 2), (2, 1), (1, 3), (3, 1)}
        net.elect(1)  # only the learner answers
        assert net.nodes[1].role is not Role.LEADER

    def test_only_a_learner_that_caught_up_may_be_promoted(self) -> None:
        net = Network(voters=1, learners=(2, 3))
        net.elect(1)
        net.isolate(3)
        net.propose(1, b"x")
        assert net.nodes[1].caught_up_learners() == {2}  # 3 never answered
        assert net.nodes[2].caught_up_learners() == frozenset()  # a learner names nobody
        net.heal()
        net.tick(1, 1)
        assert net.nodes[1].caught_up_learners() == {2, 3}

    def test_new_node_joins_as_learner_and_is_promoted(self) -> None:
        net = Network()
        net.elect(1)
        net.propose(1, b"a")
        net.add(4)
        net.nodes[1].propose_conf_change(ConfChange(ConfChangeKind.ADD_LEARNER, 4))
        net.flush()
        net.tick(1, 1)
        assert net.data(4) == [b"a"]
        assert net.nodes[4].config.learners == {4}
        net.nodes[1].propose_conf_change(ConfChange(ConfChangeKind.ADD_VOTER, 4))
        net.flush()
        assert all(n.config.voters == {1, 2, 3, 4} for n in net.nodes.values())
        net.isolate(1)
        net.tick_all((2, 3, 4), 3 * ELECTION)
        assert Role.LEADER in {net.nodes[n].role for n in (2, 3, 4)}

    def test_one_change_at_a_time(self) -> None:
        net = Network()
        leader = net.elect(1)
        net.isolate(1)
        leader.propose_conf_change(ConfChange(ConfChangeKind.ADD_LEARNER, 4))
        with pytest.raises(ProposalRefused):
            leader.propose_conf_change(ConfChange(ConfChangeKind.ADD_LEARNER, 5))

    def test_new_leader_waits_for_its_first_commit_before_a_change(self) -> None:
        net = Network(options=RaftOptions(election_tick=ELECTION, check_quorum=False))
        net.elect(1)
        net.drop = lambda m: m.kind is M.APP  # the new leader's no-op cannot commit
        leader = net.elect(2)
        assert leader.role is Role.LEADER
        change = ConfChange(ConfChangeKind.ADD_LEARNER, 4)
        with pytest.raises(ProposalRefused):
            leader.propose_conf_change(change)
        net.drop = lambda m: False
        net.tick(2, 1)
        assert leader.propose_conf_change(change)[0] == leader.log.last_index

    def test_multi_server_changes_are_rejected(self) -> None:
        with pytest.raises(ValueError, match="already"):
            Config(frozenset({1, 2})).apply(ConfChange(ConfChangeKind.ADD_VOTER, 2))
        with pytest.raises(ValueError, match="last voter"):
            Config(frozenset({1})).apply(ConfChange(ConfChangeKind.REMOVE_NODE, 1))

    def test_removed_leader_steps_down_and_the_rest_elect(self) -> None:
        net = Network()
        net.elect(1)
        net.nodes[1].propose_conf_change(ConfChange(ConfChangeKind.REMOVE_NODE, 1))
        net.flush()
        assert net.nodes[1].role is Role.FOLLOWER
        assert all(net.nodes[n].config.voters == {2, 3} for n in (1, 2, 3))
        net.tick(1, 5 * ELECTION)
        assert net.nodes[1].role is Role.FOLLOWER  # not a member: never campaigns
        net.tick_all((2, 3), 3 * ELECTION)
        assert Role.LEADER in {net.nodes[2].role, net.nodes[3].role}
        leader = 2 if net.nodes[2].role is Role.LEADER else 3
        net.propose(leader, b"after")
        assert b"after" in net.data(2)
        assert b"after" not in net.data(1)

    def test_removed_but_uncommitted_leader_may_win_again(self) -> None:
        # Simulator seed 82: the removal is appended (so in force at node 1) but not committed;
        # node 2, the last voter, lacks it and needs node 1's vote. Node 1 must campaign.
        net = Network(voters=2)
        net.elect(1)
        net.isolate(1)
        net.nodes[1].propose_conf_change(ConfChange(ConfChangeKind.REMOVE_NODE, 1))
        net.tick(1, 2 * ELECTION + 1)  # CheckQuorum: steps down before the removal commits
        assert net.nodes[1].role is Role.FOLLOWER
        net.heal()
        net.tick_all((1, 2), 3 * ELECTION)
        assert net.nodes[2].config.voters == {2}
        assert net.nodes[2].role is Role.LEADER


class TestSnapshot:
    def test_lagging_follower_installs_the_snapshot(self) -> None:
        net = Network()
        net.elect(1)
        net.isolate(3)
        net.propose(1, *[b"%d" % i for i in range(10)])
        leader = net.nodes[1]
        snap = leader.compact(leader.log.applied, b"state after 10")
        net.disks[1].save_snapshot(snap)
        net.propose(1, b"tail")
        net.heal()
        net.sent.clear()
        net.tick(1, 2)
        assert any(m.kind is M.SNAP and m.to == 3 for m in net.sent)
        follower = net.nodes[3]
        assert follower.log.snapshot == snap
        assert net.disks[3].snapshot == snap
        assert net.data(3)[-1:] == [b"tail"]
        assert follower.log.committed == leader.log.committed

    def test_restart_from_a_snapshot(self) -> None:
        net = Network()
        net.elect(1)
        net.propose(1, b"a", b"b")
        node = net.nodes[2]
        net.disks[2].save_snapshot(node.compact(node.log.applied, b"ab"))
        restarted = net.restart(2)
        assert restarted.log.first_index == node.log.first_index
        assert restarted.config == node.config

    def test_compacting_beyond_applied_is_refused(self) -> None:
        net = Network()
        net.elect(1)
        with pytest.raises(ValueError, match="compact"):
            net.nodes[1].compact(net.nodes[1].log.last_index + 1, b"")


class TestReadIndex:
    def test_leader_read_waits_for_a_heartbeat_quorum(self) -> None:
        net = Network()
        net.elect(1)
        net.propose(1, b"a")
        net.nodes[1].read_index(b"r1")
        net.flush()
        assert net.reads[1] == [ReadState(net.nodes[1].log.committed, b"r1")]

    def test_leader_without_quorum_answers_no_read(self) -> None:
        net = Network()
        net.elect(1)
        net.isolate(1)
        net.nodes[1].read_index(b"r1")
        net.flush()
        assert net.reads[1] == []

    def test_follower_read_is_forwarded_to_the_leader(self) -> None:
        net = Network()
        net.elect(1)
        net.propose(1, b"a")
        net.nodes[3].read_index(b"f")
        net.flush()
        assert net.reads[3] == [ReadState(net.nodes[1].log.committed, b"f")]

    def test_reads_that_come_during_a_round_share_the_next(self) -> None:
        net = Network()
        net.elect(1)
        net.propose(1, b"a")
        net.sent.clear()
        for context in (b"r1", b"r2", b"r3"):  # r2 and r3 while r1's round is out
            net.nodes[1].read_index(context)
        net.flush()
        committed = net.nodes[1].log.committed
        assert net.reads[1] == [ReadState(committed, c) for c in (b"r1", b"r2", b"r3")]
        rounds = [m.context for m in net.sent if m.kind is M.HEARTBEAT and m.context]
        assert rounds == [b"r1", b"r1", b"r3", b"r3"]  # two rounds of two voters, not three

    def test_a_read_round_asks_the_voters_only(self) -> None:
        net = Network(voters=3, learners=(4,))
        net.elect(1)
        net.propose(1, b"a")
        net.sent.clear()
        net.nodes[1].read_index(b"r")
        net.flush()
        assert net.reads[1] == [ReadState(net.nodes[1].log.committed, b"r")]
        asked = {m.to for m in net.sent if m.kind is M.HEARTBEAT and m.context == b"r"}
        assert asked == {2, 3}  # a learner's answer would not count

    def test_read_without_a_leader_is_refused(self) -> None:
        net = Network()
        with pytest.raises(NotLeader) as err:
            net.nodes[2].read_index(b"x")
        assert err.value.leader == NONE


class TestQuiescence:
    """An idle group goes quiet: no heartbeats, no election timers (RaftOptions.quiesce)."""

    @staticmethod
    def quiet_group() -> Network:
        net = Network(options=RaftOptions(election_tick=ELECTION, quiesce=True))
        net.elect(1)
        net.propose(1, b"a")
        net.tick_all((1, 2, 3), 3)  # a heartbeat round hears everyone, the next one quiesces
        assert all(n.quiet for n in net.nodes.values())
        return net

    def test_an_idle_group_sends_nothing_and_a_proposal_wakes_it(self) -> None:
        net = self.quiet_group()
        sent = len(net.sent)
        net.tick_all((1, 2, 3), 5 * ELECTION)  # long past any election timeout
        assert len(net.sent) == sent
        assert net.nodes[1].role is Role.LEADER
        net.propose(1, b"b")
        assert net.data(1) == net.data(2) == net.data(3) == [b"a", b"b"]
        assert not net.nodes[1].quiet

    def test_followers_whose_leader_died_elect_another(self) -> None:
        net = self.quiet_group()
        net.isolate(1)
        for _ in range(3 * ELECTION):  # the failure detector no longer hears node 1
            for nid in (2, 3):
                net.nodes[nid].tick(leader_alive=False)
            net.flush()
        assert {net.nodes[n].role for n in (2, 3)} == {Role.LEADER, Role.FOLLOWER}
        leader = next(n for n in (2, 3) if net.nodes[n].role is Role.LEADER)
        net.propose(leader, b"after")
        assert net.data(2)[-1] == net.data(3)[-1] == b"after"

    def test_a_follower_that_missed_the_quiesce_wakes_the_leader(self) -> None:
        net = Network(options=RaftOptions(election_tick=ELECTION, quiesce=True))
        net.elect(1)
        net.propose(1, b"a")
        net.drop = lambda m: m.kind is M.QUIESCE and m.to == 3
        net.tick_all((1, 2, 3), 3)
        assert net.nodes[1].quiet
        assert not net.nodes[3].quiet  # its timer runs: it will ask for votes
        net.drop = lambda m: False
        term = net.nodes[1].term
        net.tick_all((1, 2, 3), 4 * ELECTION)
        assert net.nodes[1].role is Role.LEADER  # woken by the pre-vote, it kept its group
        assert net.nodes[1].term == term
        assert all(n.quiet for n in net.nodes.values())  # and quiesced again
