"""The core (DESIGN §3): ids, clock, errors, tables, history, transactions, merge,
limits and the storage codec. Imports nothing above it; pure but for the codec."""
