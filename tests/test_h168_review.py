"""Review of 4828a58 (h168): a refused ``--scheduler`` address is tried again for
``REFUSED_GRACE_S``, but only when the probe's error is a ConnectionRefusedError. A host name
with two addresses (``localhost`` is ``::1`` and ``127.0.0.1`` on Debian) that both refuse
made asyncio's ``open_connection`` raise a plain ``OSError("Multiple exceptions: ...")``, so
``dask scheduler & bomgraph compare --scheduler tcp://localhost:8786`` was given up at once
and the refusal named as "Multiple exceptions". The probe now tries each address itself."""

from __future__ import annotations

import asyncio
import socket

import pytest

from bomgraph import cluster


def _free_port() -> int:
    with socket.socket() as s:               # closed again: refused until something listens
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _infos(*hosts: str, port: int) -> list[tuple]:
    return [i for h in hosts for i in socket.getaddrinfo(h, port, type=socket.SOCK_STREAM)]


def test_a_name_whose_addresses_all_refuse_is_a_refusal() -> None:
    port = _free_port()
    with pytest.raises(ConnectionRefusedError):
        asyncio.run(cluster._connect_any(_infos("127.0.0.2", "127.0.0.1", port=port)))


def test_the_first_address_that_listens_is_taken() -> None:
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]
        asyncio.run(cluster._connect_any(_infos("127.0.0.2", "127.0.0.1", port=port)))


def test_a_probe_of_a_refusing_address_still_says_refused() -> None:
    with pytest.raises(ConnectionRefusedError):
        asyncio.run(cluster._reachable(f"tcp://127.0.0.1:{_free_port()}", 5))


def test_methods_says_what_conversion_kl_max_does_and_real_uses() -> None:
    """``bomgraph methods ekf-invdepth`` shows an option's first sentence: c857885's entry
    began with the None case ("a feature becomes Euclidean once Civera's index passes") and
    left the number, the test and the ``real`` preset's 0.01 to later sentences."""
    from baselines.ekf import InverseDepthConfig
    from bomgraph.config import describe_options

    doc = {o.name: o.doc for o in describe_options(InverseDepthConfig)}["conversion_kl_max"]
    assert "Bailey" in doc and "0.01" in doc and '"real"' in doc and "None" in doc, doc
    assert InverseDepthConfig.preset("real").conversion_kl_max == 0.01
