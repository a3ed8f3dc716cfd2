"""The application's key: the secret the hosts of one application share, and nobody else.

Every message between hosts is authenticated with it (:mod:`.auth`): a participant of the same DDS
domain without the key can neither feed nor stop the application. The key is 32 random bytes,
written as 64 hexadecimal digits in a file readable by its owner alone (``coco-keygen FILE`` makes
one; copy it to every host as you would an SSH key), or given in an environment variable. The
launchers take ``--key FILE`` or ``--key-env NAME``; an application over several hosts refuses to
start without one (docs/hosts.md, "Who may talk to the hosts").
"""

from __future__ import annotations

import argparse
import hashlib
import os
import secrets
import stat
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from ..errors import KeyFileError

KEY_BYTES = 32
MAX_FILE_BYTES = 1024
"""A key file is 65 bytes; a larger one is not a key file (and is not read whole)."""


@dataclass(frozen=True)
class AppKey:
    """The application's key and where it came from (for messages: never the key itself)."""

    secret: bytes = field(repr=False)
    origin: str

    def __post_init__(self) -> None:
        if len(self.secret) != KEY_BYTES:
            raise KeyFileError(f"{self.origin}: a key is {KEY_BYTES} bytes, got {len(self.secret)}")

    @property
    def fingerprint(self) -> str:
        """A short digest that tells two keys apart in a log without saying anything of the key:
        the hosts of one application print the same one."""
        return hashlib.sha256(b"coco key fingerprint\0" + self.secret).hexdigest()[:16]

    @classmethod
    def from_text(cls, text: str, origin: str) -> AppKey:
        digits = text.strip()
        if len(digits) != 2 * KEY_BYTES:
            raise KeyFileError(f"{origin}: a key is {2 * KEY_BYTES} hexadecimal digits (coco-keygen FILE makes one), "
                               f"got {len(digits)} characters")
        try:
            return cls(bytes.fromhex(digits), origin)
        except ValueError:
            raise KeyFileError(f"{origin}: a key is {2 * KEY_BYTES} hexadecimal digits; this is not "
                               "(coco-keygen FILE makes one)") from None

    @classmethod
    def from_file(cls, path: str) -> AppKey:
        """The key in ``path``: a regular file of its owner alone (as ssh wants a private key), at
        most :data:`MAX_FILE_BYTES` long."""
        origin = f"key file {path}"
        try:
            descriptor = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
        except OSError as error:
            raise KeyFileError(f"{origin}: cannot be opened ({error.strerror})") from None
        status = os.fstat(descriptor)
        if not stat.S_ISREG(status.st_mode):
            os.close(descriptor)
            raise KeyFileError(f"{origin}: not a regular file")
        with os.fdopen(descriptor, "rb") as file:
            if status.st_mode & 0o077:
                raise KeyFileError(f"{origin}: readable or writable by others (mode {stat.S_IMODE(status.st_mode):04o}); "
                                   f"only its owner may: chmod 600 {path}")
            data = file.read(MAX_FILE_BYTES + 1)
        if len(data) > MAX_FILE_BYTES:
            raise KeyFileError(f"{origin}: larger than {MAX_FILE_BYTES} bytes: not a key file")
        try:
            return cls.from_text(data.decode("ascii"), origin)
        except UnicodeDecodeError:
            raise KeyFileError(f"{origin}: not a key file (not text)") from None

    @classmethod
    def from_environment(cls, name: str) -> AppKey:
        value = os.environ.get(name)
        if value is None:
            raise KeyFileError(f"environment variable {name} (--key-env) is not set")
        return cls.from_text(value, f"environment variable {name}")


def launch_key(options: Any) -> AppKey | None:
    """The key the launch options name (``--key FILE`` or ``--key-env NAME``), None when neither."""
    if options.key is not None and options.key_env is not None:
        raise KeyFileError("give the application's key once: --key FILE or --key-env NAME, not both")
    if options.key is not None:
        return AppKey.from_file(options.key)
    if options.key_env is not None:
        return AppKey.from_environment(options.key_env)
    return None


def write_key(path: str, force: bool = False) -> AppKey:
    """A new key in a new file ``path`` (mode 0600); an existing file is kept unless ``force``."""
    secret = secrets.token_bytes(KEY_BYTES)
    flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | (os.O_TRUNC if force else os.O_EXCL)
    try:
        descriptor = os.open(path, flags, 0o600)
    except FileExistsError:
        raise KeyFileError(f"key file {path}: exists already (--force replaces it)") from None
    except OSError as error:
        raise KeyFileError(f"key file {path}: cannot be written ({error.strerror})") from None
    with os.fdopen(descriptor, "w") as file:
        os.fchmod(file.fileno(), 0o600)
        file.write(secret.hex() + "\n")
    return AppKey(secret, f"key file {path}")


def keygen(argv: Sequence[str] | None = None) -> int:
    """``coco-keygen FILE``: make an application key."""
    parser = argparse.ArgumentParser(prog="coco-keygen", description=(
        "Make a key for an application over several hosts: 32 random bytes in FILE (mode 0600). Copy it to "
        "every host and start each with --key FILE."))
    parser.add_argument("file")
    parser.add_argument("--force", action="store_true", help="replace FILE if it exists")
    options = parser.parse_args(argv)
    try:
        key = write_key(options.file, options.force)
    except KeyFileError as error:
        print(f"coco-keygen: {error}", file=sys.stderr)
        return 1
    print(f"wrote {options.file} (fingerprint {key.fingerprint}): copy it to every host, then start each with "
          f"--key {options.file}")
    return 0
