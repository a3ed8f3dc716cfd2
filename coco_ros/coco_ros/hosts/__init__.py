"""The host level over DDS (docs/hosts.md)."""
