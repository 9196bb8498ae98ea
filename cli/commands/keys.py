"""`vstig keys`: a swarm's master secret, and the key each robot's firmware holds (SPEC.md 10.1)."""

from __future__ import annotations

import os

import click

from vstig_hw.auth import KEY_SIZE, new_swarm_key_text, robot_key
from vstig_hw.wire import U16_MAX

from ..swarm_key import SWARM_KEY

_ROBOT = click.IntRange(0, U16_MAX)


def c_initializer(robot: int, key: bytes) -> str:
    """`key` as the array libvstig's vstig_tag_key_init takes, named for its robot."""
    rows = [", ".join(f"0x{byte:02x}" for byte in key[i : i + 8]) for i in range(0, KEY_SIZE, 8)]
    body = ",\n    ".join(rows)
    return f"/* robot {robot}: vstig keys; keep it out of version control */\n" \
           f"static const uint8_t vstig_own_key[VSTIG_KEY_SIZE] = {{\n    {body}}};"


def _write_new(path: str) -> None:
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        raise click.ClickException(f"{path}: already exists; a swarm key is never overwritten (every robot's "
                                   "key derives from it): remove it first, or give another FILE") from None
    except OSError as error:
        raise click.ClickException(f"{path}: cannot write the swarm key file: {error.strerror}") from None
    with os.fdopen(fd, "w", encoding="ascii") as file:
        file.write(new_swarm_key_text())
    click.echo(f"{path}: a new swarm key (mode 600); give it to every gateway with --swarm-key {path}", err=True)


@click.command()
@click.argument("robots", nargs=-1, type=_ROBOT, metavar="[ROBOT]...")
@click.option("--swarm-key", "master", type=SWARM_KEY, help="The swarm's master secret (64 hex digits, mode 600).")
@click.option("--new", "new_path", metavar="FILE", help="Write a fresh master secret to FILE (never overwrites).")
@click.option("--format", "form", type=click.Choice(["hex", "c"]), default="hex", show_default=True,
              help="hex: 'ROBOT KEY' lines; c: the array libvstig's vstig_tag_key_init takes.")
def command(robots: tuple[int, ...], master: bytes | None, new_path: str | None, form: str) -> None:
    """Derive each ROBOT's key from the swarm key, for its firmware; or make a swarm key with --new FILE.

    A robot holds only its own key, so a captured robot can forge no other robot's writes; gateways hold the
    swarm key and check every writer.
    """
    if new_path is not None:
        if master is not None or robots:
            raise click.UsageError("--new FILE makes a swarm key; derive robot keys from it in a second run")
        _write_new(new_path)
        return
    if master is None:
        raise click.UsageError("give --swarm-key FILE (and the ROBOT ids), or --new FILE to make one")
    if not robots:
        raise click.UsageError("name the ROBOT ids whose keys to derive (0..65535)")
    for robot in robots:
        key = robot_key(master, robot)
        click.echo(c_initializer(robot, key) if form == "c" else f"{robot} {key.hex()}")
