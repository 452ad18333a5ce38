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

VIRTUAL_INTERFACES = ("docker", "br-", "veth", "virbr", "vnet", "podman", "cni", "flannel",
                      "lxc", "lxd", "vmnet", "vboxnet")
"""Prefixes of the names of interfaces that lead to containers or virtual machines on this
machine, not to the classroom: their addresses come last."""


def lan_addresses() -> list[str]:
    """This machine's IPv4 addresses others on its networks can reach, likeliest first.

    The first is what the banner and the links name (``sites.public_host``): an address of a
    real interface before one of a container bridge, a private network's (a classroom's
    Wi-Fi: 10/8, 172.16/12, 192.168/16) before others, then in order.
    """
    found: dict[ipaddress.IPv4Address, bool] = {}
    for interface, addresses in psutil.net_if_addrs().items():
        virtual = interface.startswith(VIRTUAL_INTERFACES)
        for address in addresses:
            if address.family != socket.AF_INET:
                continue
            ip = ipaddress.IPv4Address(address.address)
            if not (ip.is_loopback or ip.is_link_local or ip.is_unspecified):
                found[ip] = found.get(ip, True) and virtual
    return [str(ip) for ip in sorted(found, key=lambda ip: (found[ip], not ip.is_private, ip))]


def qr_lines(text: str) -> list[str]:
    """``text`` as a QR code drawn with block characters, two rows of modules a line."""
    out = io.StringIO()
    segno.make(text, error="m").terminal(out=out, compact=True, border=2)
    return out.getvalue().rstrip("\n").splitlines()
