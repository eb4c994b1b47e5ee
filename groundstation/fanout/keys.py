"""CURVE key pairs for consoles beyond loopback: who may subscribe to a publisher.

One folder holds a lab's keys (`groundstation fanout keys DIR [--name NAME]`):

    DIR/publisher.public, DIR/publisher.secret   the publisher's pair (made once)
    DIR/NAME.public, DIR/NAME.secret             a viewer's pair (one per console/person)
    DIR/authorized/NAME.public                   the viewers the publisher lets in

Each file is one Z85 key (40 characters) on a line; secret files are made readable by
their owner only.  The publisher needs publisher.* and authorized/; a viewer machine
needs publisher.public and its own NAME.* (copy them there).  The publisher re-reads
authorized/ at each new connection, so removing a file there locks that viewer out of
its next connection without a restart.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

from .endpoints import FanoutError

log = logging.getLogger(__name__)

PUBLISHER = "publisher"
AUTHORIZED = "authorized"


@dataclass(frozen=True)
class KeyPair:
    public: bytes
    secret: bytes | None


def _write(path: Path, key: bytes, secret: bool) -> None:
    path.write_bytes(key + b"\n")
    if secret:
        os.chmod(path, 0o600)


def _read(path: Path) -> bytes:
    try:
        key = path.read_bytes().strip()
    except OSError as exc:
        raise FanoutError(f"CURVE key {path}: {exc.strerror or exc} - make the keys with "
                          f"`groundstation fanout keys {path.parent}`") from None
    if len(key) != 40:
        raise FanoutError(f"CURVE key {path}: expected 40 Z85 characters, found {len(key)} - "
                          f"not a key made by `groundstation fanout keys`")
    return key


def make_keys(folder: str | Path, name: str = "viewer") -> list[Path]:
    """The publisher's pair (if the folder has none yet) and a viewer pair `name`,
    authorised; returns the files written.  An existing viewer pair is never replaced."""
    import zmq

    if not name or "/" in name or name in (PUBLISHER, AUTHORIZED):
        raise FanoutError(f"'{name}' cannot name a viewer's key pair")
    root = Path(folder)
    (root / AUTHORIZED).mkdir(parents=True, exist_ok=True)
    written = []
    for who in (PUBLISHER, name):
        if (root / f"{who}.secret").exists():
            if who == name:
                raise FanoutError(f"{root / (who + '.secret')} exists: choose another --name, "
                                  f"or delete the old pair first")
            continue
        public, secret = zmq.curve_keypair()
        _write(root / f"{who}.public", public, False)
        _write(root / f"{who}.secret", secret, True)
        written += [root / f"{who}.public", root / f"{who}.secret"]
    _write(root / AUTHORIZED / f"{name}.public", _read(root / f"{name}.public"), False)
    written.append(root / AUTHORIZED / f"{name}.public")
    return written


def load_pair(folder: str | Path, name: str, *, secret: bool = True) -> KeyPair:
    root = Path(folder)
    return KeyPair(_read(root / f"{name}.public"),
                   _read(root / f"{name}.secret") if secret else None)


def authorized_keys(folder: str | Path) -> set[bytes]:
    """The viewers' public keys the publisher accepts (Z85)."""
    return {_read(p) for p in sorted((Path(folder) / AUTHORIZED).glob("*.public"))}


class _Authorised:
    """The ZAP callback: a client key is let in if authorized/ holds it (read per call)."""

    def __init__(self, folder: Path):
        self.folder = folder

    def callback(self, domain: str, key: bytes) -> bool:
        try:
            ok = key in authorized_keys(self.folder)
        except FanoutError as exc:
            log.error("checking a viewer's key: %s", exc)
            return False
        if not ok:
            log.warning("a viewer with an unknown CURVE key was refused")
        return ok


def secure_publisher(context, socket, folder: str | Path):
    """Make `socket` a CURVE server that admits only authorised viewers.  Returns the
    authenticator (a thread of pyzmq's; stop() it when the socket closes)."""
    from zmq.auth.thread import ThreadAuthenticator

    pair = load_pair(folder, PUBLISHER)
    if not authorized_keys(folder):
        raise FanoutError(f"{Path(folder) / AUTHORIZED} holds no viewer key: no one could "
                          f"subscribe - add one with `groundstation fanout keys {folder} --name NAME`")
    auth = ThreadAuthenticator(context)
    auth.start()
    auth.configure_curve_callback("*", _Authorised(Path(folder)))
    socket.curve_secretkey = pair.secret
    socket.curve_publickey = pair.public
    socket.curve_server = True
    return auth


def secure_viewer(socket, folder: str | Path, name: str = "viewer") -> None:
    """Make `socket` a CURVE client with its pair `name`, trusting the lab's publisher key."""
    pair = load_pair(folder, name)
    socket.curve_serverkey = load_pair(folder, PUBLISHER, secret=False).public
    socket.curve_publickey = pair.public
    socket.curve_secretkey = pair.secret
