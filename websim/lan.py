"""What students type: this machine's addresses on the network, and a QR code of a page.

With ``--host 0.0.0.0`` the server is reachable at every address of the machine; the banner
lists the IPv4 ones a classroom can use (not loopback, not link-local) and draws the page's
URL as a QR code in the terminal, for phones (psutil lists the addresses, segno draws the
code: no network is needed for either).
"""

from __future__ import annotations

import io
import ipaddress
import socket

import psutil
import segno


def lan_addresses() -> list[str]:
    """This machine's IPv4 addresses others on its networks can reach, sorted."""
    found = set()
    for addresses in psutil.net_if_addrs().values():
        for address in addresses:
            if address.family != socket.AF_INET:
                continue
            ip = ipaddress.IPv4Address(address.address)
            if not (ip.is_loopback or ip.is_link_local or ip.is_unspecified):
                found.add(ip)
    return [str(ip) for ip in sorted(found)]


def qr_lines(text: str) -> list[str]:
    """``text`` as a QR code drawn with block characters, two rows of modules a line."""
    out = io.StringIO()
    segno.make(text, error="m").terminal(out=out, compact=True, border=2)
    return out.getvalue().rstrip("\n").splitlines()
