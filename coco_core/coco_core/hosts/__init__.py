"""The scheduling tree's host level: one application over several machines (``docs/hosts.md``)."""
