"""The swarm (DESIGN §3, §5-§8): membership, liveness and failure detection,
the commit path across holders, replication, recovery, triggers and subscriptions."""
