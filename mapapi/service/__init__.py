"""The service (DESIGN §3, §9): the `Peer` facade, the repository on disk, the
daemon and its control endpoint, named views and the operations behind `mapctl`."""
