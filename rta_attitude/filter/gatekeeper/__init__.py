"""The gatekeeper (`filter.backup_law`): the filter applies its answer only while a rollout of it, then a backup
law, stays safe on the filter's model; else the backup law's verified plan (docs/backup.md).

- `records`: its parameters and memory (BACKUP_DTYPE, GATE_DTYPE);
- `law`: the backup law (the backup attitude, its targets for a large momentum, the terminal set);
- `rollout`: the check of a candidate over the horizon, its margins and the energy reserve;
- `gate`: which command a call applies (verify, commit, follow a plan);
- `plans`: the plans over the filter's own answers, and the gatekeeper's part of a call (`gate_call`).
"""
