"""OpenStreetMap sources: a local .osm file, a download from a loopback Overpass server (cached), offline errors.

Nothing here leaves the machine: a guard refuses any socket connection to a non-loopback address.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import json
import socket
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs

import pytest

from dtradar_data.core.errors import CorruptDatasetError, DtradarError
from dtradar_data.scenes.city.footprints import CITY_BOXES, FootprintsEmptyError, FootprintsUnavailableError
from dtradar_data.scenes.city.osm import cache_paths, download_osm, read_osm_xml
from dtradar_data.scenes.city.sources import load_footprints

ox = pytest.importorskip("osmnx")

FIXTURE = Path(__file__).parent / "fixtures" / "tiny_houston.osm"
BOX, CRS = CITY_BOXES["houston"]
# A plausible Overpass /api/status reply: osmnx 2.x reads its 5th line ("N slots available now." -> no pause).
STATUS_TEXT = (
    "Connected as: 2130706433\nCurrent time: 2026-01-01T00:00:00Z\nAnnounced endpoint: none\n"
    "Rate limit: 2\n2 slots available now.\nCurrently running queries (pid, space limit, time limit, "
    "start time):\n"
)


@pytest.fixture(autouse=True)
def loopback_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """Refuse connections to anything but loopback, so a wrong setting fails the test instead of going online."""
    real_connect = socket.socket.connect

    def connect(self: socket.socket, address: object) -> None:
        if self.family in (socket.AF_INET, socket.AF_INET6):
            host = address[0]  # type: ignore[index]
            if not ipaddress.ip_address(host).is_loopback:
                raise ConnectionRefusedError(f"test guard: refused a connection to non-loopback {host}")
        return real_connect(self, address)

    monkeypatch.setattr(socket.socket, "connect", connect)


def overpass_json_from_osm_xml(path: Path) -> dict:
    """The fixture's nodes, ways and relations in the Overpass API's JSON ``out`` format."""
    elements = []
    for el in ET.parse(path).getroot():
        tags = {t.get("k"): t.get("v") for t in el.findall("tag")}
        item: dict = {"type": el.tag, "id": int(el.get("id", 0))}
        if el.tag == "node":
            item.update(lat=float(el.get("lat")), lon=float(el.get("lon")))
        elif el.tag == "way":
            item["nodes"] = [int(nd.get("ref")) for nd in el.findall("nd")]
        elif el.tag == "relation":
            item["members"] = [
                {"type": m.get("type"), "ref": int(m.get("ref")), "role": m.get("role")} for m in el.findall("member")
            ]
        else:
            continue  # <bounds>
        if tags:
            item["tags"] = tags
        elements.append(item)
    return {
        "version": 0.6,
        "generator": "Overpass API (dtradar test double)",
        "osm3s": {
            "timestamp_osm_base": "2026-01-01T00:00:00Z",
            "copyright": "The data included in this document is from www.openstreetmap.org. "
            "The data is made available under ODbL.",
        },
        "elements": elements,
    }


class FakeOverpass:
    """An Overpass API double on 127.0.0.1: GET /api/status, GET or POST /api/interpreter; records each request."""

    def __init__(self, payload: dict, interpreter_status: int = 200):
        self.payload = json.dumps(payload).encode()
        self.interpreter_status = interpreter_status
        self.requests: list[tuple[str, str, str]] = []  # (method, path, query text)
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def _answer(self, method: str, body: str) -> None:
                path, _, query = self.path.partition("?")
                outer.requests.append((method, path, parse_qs(body or query).get("data", [""])[0]))
                if path == "/api/status":
                    self._send(200, "text/plain", STATUS_TEXT.encode())
                elif path == "/api/interpreter" and outer.interpreter_status != 200:
                    self._send(outer.interpreter_status, "text/html", b"<html>runtime error</html>")
                elif path == "/api/interpreter":
                    self._send(200, "application/json", outer.payload)
                else:
                    self._send(404, "text/plain", b"not found")

            def _send(self, code: int, ctype: str, data: bytes) -> None:
                self.send_response(code)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def do_GET(self) -> None:  # noqa: N802
                self._answer("GET", "")

            def do_POST(self) -> None:  # noqa: N802
                length = int(self.headers.get("Content-Length", "0"))
                self._answer("POST", self.rfile.read(length).decode())

            def log_message(self, *args: object) -> None:  # keep pytest output clean
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/api"
        self.thread = threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
        self.thread.start()
        self.running = True

    def stop(self) -> None:
        if self.running:
            self.running = False
            self.server.shutdown()
            self.server.server_close()
            self.thread.join(timeout=5)


@pytest.fixture
def overpass(monkeypatch: pytest.MonkeyPatch) -> Iterator[FakeOverpass]:
    server = FakeOverpass(overpass_json_from_osm_xml(FIXTURE))
    monkeypatch.delenv("DTRADAR_OVERPASS_URL", raising=False)
    monkeypatch.delenv("DTRADAR_OFFLINE", raising=False)
    monkeypatch.setattr(ox.settings, "overpass_url", server.url)  # restored by monkeypatch after the test
    try:
        yield server
    finally:
        server.stop()
        assert not server.thread.is_alive()


@pytest.fixture
def data_root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path))
    return tmp_path


def closed_loopback_url() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return f"http://127.0.0.1:{port}/api"  # nothing listens there now: connection refused


# --- local XML ------------------------------------------------------------------------------------------------------


def test_a_local_osm_file_gives_buildings_parking_and_roads_with_their_tags():
    fp = read_osm_xml(FIXTURE, BOX, CRS)
    assert fp.counts() == {"building": 7, "parking": 1, "road": 3}
    by_id = {f.source_id: f for f in fp.features}
    assert (by_id["way/101"].height_m, by_id["way/101"].height_source, by_id["way/101"].label) == (
        45.0,
        "height",
        "Test Tower A",
    )
    assert by_id["way/102"].height_m == pytest.approx(45.72) and by_id["way/102"].material == "glass"
    assert (by_id["way/103"].height_m, by_id["way/103"].material) == (17.5, "brick")
    assert (by_id["way/104"].height_source, by_id["way/104"].material) == ("default", "marble")
    assert (by_id["way/105"].height_m, by_id["way/105"].material_source) == (105.0, "rule")
    assert len(by_id["relation/401"].holes) == 1  # multipolygon relation with a courtyard
    assert by_id["way/201"].kind == "parking" and by_id["way/301"].subtype == "primary"
    r = fp.report
    assert r["clipped"] == {"building": 1, "parking": 0, "road": 1}
    assert r["dropped_outside"]["building"] == 1  # way/106 lies east of the box
    assert r["skipped"] == {"point_geometry": 1, "underground_parking": 1}
    assert fp.licence == "ODbL-1.0" and "OpenStreetMap contributors" in fp.attribution
    assert fp.retrieved_utc is None and str(FIXTURE) in fp.source


def test_load_footprints_dispatches_osm_files_by_extension():
    assert load_footprints(FIXTURE, BOX, CRS).features == read_osm_xml(FIXTURE, BOX, CRS).features


def test_a_broken_osm_file_is_a_typed_error(tmp_path):
    bad = tmp_path / "bad.osm"
    bad.write_text("<osm><node id='1' lat='29.7' lon='-95.3'>", encoding="utf-8")
    with pytest.raises(DtradarError, match="bad.osm"):
        load_footprints(bad, BOX, CRS)


# --- download through a loopback Overpass server --------------------------------------------------------------------


def test_a_download_from_overpass_is_cached_and_read_back_without_the_server(overpass, data_root):
    started = dt.datetime.now(dt.timezone.utc).replace(microsecond=0)
    use_cache, getaddrinfo = ox.settings.use_cache, socket.getaddrinfo
    first = load_footprints("osm", BOX, CRS)  # cache_dir defaults to <data root>/osm

    assert first.counts() == {"building": 7, "parking": 1, "road": 3}
    assert first.report["dropped_outside"]["building"] == 0  # osmnx already left out way/106 (outside the box)
    assert first.features == read_osm_xml(FIXTURE, BOX, CRS).features  # the same footprints as from the file
    assert first.licence == "ODbL-1.0" and overpass.url in first.source
    retrieved = dt.datetime.fromisoformat(first.retrieved_utc.replace("Z", "+00:00"))
    assert started <= retrieved <= dt.datetime.now(dt.timezone.utc)

    methods_paths = {(m, p) for m, p, _ in overpass.requests}
    assert ("GET", "/api/status") in methods_paths and ("POST", "/api/interpreter") in methods_paths
    query = next(q for m, p, q in overpass.requests if p == "/api/interpreter")
    assert query.startswith("[out:json][timeout:180];")  # Overpass wants a whole number of seconds
    assert "['building']" in query and "['amenity'='parking']" in query and "['highway']" in query

    geojson_path, meta_path = cache_paths(BOX, data_root / "osm")
    assert sorted(p.name for p in (data_root / "osm").iterdir()) == sorted([geojson_path.name, meta_path.name])
    meta = json.loads(meta_path.read_text())
    assert meta["retrieved_utc"] == first.retrieved_utc and meta["overpass_url"] == overpass.url
    assert ox.settings.use_cache == use_cache and socket.getaddrinfo is getaddrinfo  # settings restored

    overpass.stop()
    count = len(overpass.requests)
    second = load_footprints("osm", BOX, CRS)
    offline = download_osm(BOX, CRS, data_root / "osm", offline=True)
    assert second == first == offline  # same features, report and retrieved_utc
    assert len(overpass.requests) == count


def test_the_overpass_url_comes_from_the_environment_variable(overpass, tmp_path, monkeypatch):
    monkeypatch.setattr(ox.settings, "overpass_url", closed_loopback_url())
    monkeypatch.setenv("DTRADAR_OVERPASS_URL", overpass.url)
    fp = download_osm(BOX, CRS, tmp_path / "osm", timeout_s=10)
    assert fp.counts()["building"] == 7 and overpass.requests


def test_a_damaged_cache_is_reported_not_silently_used(overpass, tmp_path):
    download_osm(BOX, CRS, tmp_path, timeout_s=10)
    geojson_path, meta_path = cache_paths(BOX, tmp_path)
    geojson_path.write_text(geojson_path.read_text().replace("primary", "tertiary"))
    with pytest.raises(CorruptDatasetError, match="does not match its sidecar") as err:
        download_osm(BOX, CRS, tmp_path, offline=True)
    assert "refresh=True" in str(err.value)
    assert download_osm(BOX, CRS, tmp_path, refresh=True, timeout_s=10).counts()["road"] == 3


def test_a_server_error_is_the_unavailable_error_and_nothing_is_cached(tmp_path, monkeypatch):
    server = FakeOverpass({}, interpreter_status=500)
    try:
        monkeypatch.setenv("DTRADAR_OVERPASS_URL", server.url)
        with pytest.raises(FootprintsUnavailableError, match="download from .* failed"):
            download_osm(BOX, CRS, tmp_path / "osm", offline=False, timeout_s=10)
    finally:
        server.stop()
    assert list(tmp_path.rglob("*")) == []


def test_an_empty_answer_for_the_box_is_a_typed_error_and_nothing_is_cached(tmp_path, monkeypatch):
    server = FakeOverpass(overpass_json_from_osm_xml(FIXTURE) | {"elements": []})
    try:
        monkeypatch.setenv("DTRADAR_OVERPASS_URL", server.url)
        with pytest.raises(FootprintsEmptyError, match="returned no building"):
            download_osm(BOX, CRS, tmp_path / "osm", offline=False, timeout_s=10)
    finally:
        server.stop()
    assert list(tmp_path.rglob("*")) == []


def test_the_guard_refuses_connections_beyond_loopback():
    with socket.socket() as s, pytest.raises(ConnectionRefusedError, match="test guard"):
        s.connect(("192.0.2.1", 80))  # TEST-NET-1: never reached, the guard stops it first


# --- no cache and no network ----------------------------------------------------------------------------------------


def test_offline_without_a_cache_raises_one_error_naming_both_ways_out_and_writes_nothing(data_root, monkeypatch):
    monkeypatch.setenv("DTRADAR_OFFLINE", "1")
    with pytest.raises(FootprintsUnavailableError) as err:
        load_footprints("osm", BOX, CRS)
    message = str(err.value)
    assert isinstance(err.value, DtradarError) and isinstance(err.value, RuntimeError)
    assert "Overpass" in message and "internet" in message and "DTRADAR_OVERPASS_URL" in message
    assert "osmnx.settings.overpass_url" in message
    assert "make dataset SCENE=houston OSM=path/to/houston.osm" in message and "houston.geojson" in message
    assert list(data_root.rglob("*")) == []


def test_an_unreachable_server_without_a_cache_fails_fast_with_the_same_error(tmp_path, monkeypatch):
    monkeypatch.setenv("DTRADAR_OVERPASS_URL", closed_loopback_url())
    monkeypatch.delenv("DTRADAR_OFFLINE", raising=False)
    started = time.monotonic()
    with pytest.raises(FootprintsUnavailableError, match="could not be reached") as err:
        download_osm(BOX, CRS, tmp_path / "osm", offline=False, timeout_s=5)
    assert time.monotonic() - started < 5
    assert "OSM=path/to/houston.osm" in str(err.value)
    assert list(tmp_path.rglob("*")) == []


def test_the_houston_scene_downloads_its_footprints_and_records_the_download(overpass, data_root):
    from dtradar_data.scenes import load_scene_spec

    spec = load_scene_spec("houston-q2", "blueprint")  # the scene file says footprints = "osm"
    fp = spec.provenance["footprints"]
    assert fp["counts"] == {"building": 7, "parking": 1, "road": 3} and overpass.url in fp["source"]
    assert fp["retrieved_utc"] and spec.licence == "ODbL-1.0"
    assert spec.count_by_kind()["parking"] == 1 and (data_root / "osm").is_dir()
