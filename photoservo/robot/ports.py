"""Which serial port the arm's bridge is on (`photoservo find-port`): pyserial's list of ports,
plus any paths given (a pty of `photoservo pa10-sim`, a pyserial URL), each optionally asked
for the bridge's HELLO -> VERSION (docs/protocol.md).

Asking writes one HELLO frame to the port at the [link] baud: only ask ports that may hold the
bridge (`probe=False` lists them without writing).
"""

from __future__ import annotations

from dataclasses import dataclass

from serial.tools import list_ports

from photoservo.robot.link import Link, LinkError, LinkParams


@dataclass(frozen=True)
class PortInfo:
    """A serial port: `device` path or URL, pyserial's description and hardware id ('' for a
    given path), and the bridge's answer to HELLO (`bridge`: a one-line description of its
    VERSION, None when not asked or no bridge answered; `why`: what happened instead)."""

    device: str
    description: str
    hwid: str
    bridge: str | None
    why: str

    def describe(self) -> str:
        head = f"{self.device}: {self.description or '-'}" + (f" [{self.hwid}]" if self.hwid and self.hwid != "n/a" else "")
        return f"{head}; {'BRIDGE ' + self.bridge if self.bridge else self.why}"


def ask_bridge(port: str, params: LinkParams) -> tuple[str | None, str]:
    """(description of the bridge's VERSION, '') when a bridge answers HELLO on `port`, else
    (None, why not)."""
    link = Link(port, params)
    try:
        v = link.open()
    except LinkError as e:
        return None, f"no bridge ({str(e).split('. ')[0]})"
    finally:
        link.close()
    return (f"answers: firmware {v.firmware}, {v.n_joints} joints, control period "
            f"{v.control_period_us} us, state every {v.state_period_us} us"), ""


def find_ports(params: LinkParams, extra: tuple[str, ...] = (), probe: bool = True) -> list[PortInfo]:
    """pyserial's ports (sorted by device) and then `extra`, each asked for the bridge when
    `probe`."""
    ports = [(p.device, p.description, p.hwid) for p in sorted(list_ports.comports(), key=lambda p: p.device)]
    ports += [(x, "", "") for x in extra if x not in {d for d, _, _ in ports}]
    out = []
    for device, desc, hwid in ports:
        bridge, why = ask_bridge(device, params) if probe else (None, "not asked")
        out.append(PortInfo(device, desc if desc != "n/a" else "", hwid, bridge, why))
    return out
