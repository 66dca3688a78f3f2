"""Publish dataset versions to, and pull them from, Hugging Face Hub dataset repos.

One Hub repo per ``scene/variant`` (default ``dtradar/dtradar-<scene>-<variant>``; ``--repo`` overrides). A repo's
files are exactly a stored version directory (``cells.parquet``, ``paths.parquet``, ``coverage.png``, ``meta.json``,
the traced scene under ``scene/``) plus a freshly rendered ``README.md`` card whose ``configs`` point at those files.
Each publish is one commit (``HfApi.create_commit``) tagged twice: with the local tag (``v0``) and with the content
version hash, so both spellings of a revision resolve on the Hub as they do locally.

The network calls are kept to a few lines; everything around them (what is uploaded, verification, installing into
the store) runs offline. A pull downloads into a held stage under ``<root>/work/`` (a killed pull's is removed by
the next pull or build: :func:`dtradar_data.store.writing.clean_stages`), checks every sha256 recorded in
``meta.json`` and the Parquet schemas, and only then renames the version into the store: without network, without
a token or with ``HF_HUB_OFFLINE=1`` a :class:`HubError` says so and the local store is untouched; its hint names
what to do for that very dataset (the copy already here, or the build that makes it). A pull of a revision already
stored downloads nothing: :func:`pull_version` says what a pull did (:meth:`PullResult.describe`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dtradar_data.core import layout as P
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DatasetNotFoundError,
    DtradarError,
    HubError,
    InvalidSettingError,
    RevisionNotFoundError,
)
from dtradar_data.core.ids import HASH_RE, MIN_HASH_PREFIX, DatasetId, is_hash, is_tag
from dtradar_data.store import listing, local, writing
from dtradar_data.store.card import default_hub_repo, render_version_card
from dtradar_data.store.catalog import as_id, build_command, missing_twin
from dtradar_data.store.staging import held_stage
from dtradar_data.store.versions import read_refs

#: Files a Hub repo may hold for one version; anything else in the repo (e.g. .gitattributes) is left alone.
# every file of a version but its card (rendered for the Hub); the pictures only where the version has them
DATA_FILES = (P.CELLS_FILE, P.PATHS_FILE, *P.PICTURE_FILES, P.META_FILE)
#: The scene folder's files travel too; they are named by ``meta.json`` (a version's meshes depend on its materials).
SCENE_PATTERN = f"{P.SCENE_DIR}/*"


def version_files(vdir: Path, meta: dict) -> list[str]:
    """What a publish of the version in ``vdir`` uploads, besides its card: its data files and its scene's files."""
    scene = sorted(f for f in meta.get("files") or {} if P.is_scene_file(f))
    return [f for f in DATA_FILES if (vdir / f).is_file()] + scene


def default_repo(did: DatasetId) -> str:
    return default_hub_repo(did.name)


def check_repo_id(repo_id: str) -> str:
    """``repo_id`` if the Hub accepts it as a repo id, else :class:`InvalidSettingError` naming ``--repo``; checked
    before anything is verified, uploaded or downloaded."""
    from huggingface_hub.utils import HFValidationError, validate_repo_id

    try:
        validate_repo_id(repo_id)
    except HFValidationError as exc:
        raise InvalidSettingError(
            f"--repo {repo_id!r} is not a Hub repo id: {exc}",
            hint="use OWNER/NAME, e.g. dtradar/dtradar-cubicle-blueprint",
        ) from exc
    return repo_id


def offline() -> bool:
    """``HF_HUB_OFFLINE`` read now (huggingface_hub reads it once at import, which tests and users can't undo)."""
    from huggingface_hub import constants

    return os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in {"1", "true", "yes", "on"} or bool(
        constants.HF_HUB_OFFLINE
    )


def endpoint() -> str | None:
    """``HF_ENDPOINT`` read now, for the same reason; None means huggingface_hub's default."""
    return os.environ.get("HF_ENDPOINT") or None


@contextlib.contextmanager
def hub_errors(action: str, repo_id: str, *, what: str | None = None, instead: str | None = None) -> Iterator[None]:
    """Turn huggingface_hub / network exceptions into one :class:`HubError` that says what happened and what to do.

    ``what`` names what a pull asked for (``cubicle/blueprint@v3``; None: the Hub's newest version); ``instead`` is
    what its user can do without the Hub (the copy already here, or the build that makes it, its scene filled in). A
    publish gives neither: its only fix is to reach the Hub, so its hint says how to retry."""
    from huggingface_hub import errors as hf

    where = endpoint() or "https://huggingface.co"
    moved = "uploaded" if action.startswith("publish") else "downloaded"

    def unreachable(exc: BaseException) -> HubError:
        return HubError(
            f"cannot {action} {repo_id!r}: the Hub at {where} could not be reached ({exc}); nothing was {moved}",
            hint=_retry_hint(instead),
        )

    try:
        yield
    except DtradarError:
        raise
    except hf.RepositoryNotFoundError as exc:
        raise HubError(
            f"cannot {action}: the Hub repo {repo_id!r} does not exist or your token cannot see it",
            hint="check --repo, and log in with `hf auth login` (or set HF_TOKEN)",
        ) from exc
    except hf.RevisionNotFoundError as exc:
        raise HubError(
            f"cannot {action}: {repo_id!r} has no such revision on the Hub",
            hint="list its tags on the Hub page, or publish that version first",
        ) from exc
    except hf.LocalEntryNotFoundError as exc:
        if offline():
            newest = ", so the Hub cannot be asked for its newest version"
            why = f" and {what} is not in the local store" if what else newest
            raise HubError(
                f"cannot {action} {repo_id!r}: offline mode is on (HF_HUB_OFFLINE=1){why}; nothing was {moved}",
                hint="unset HF_HUB_OFFLINE on a machine with network access and run the same command again"
                + (f", or {instead}" if instead else ""),
            ) from exc
        raise unreachable(exc.__cause__ or exc) from exc
    except hf.HfHubHTTPError as exc:
        status = getattr(getattr(exc, "response", None), "status_code", None)
        if status in (401, 403):
            raise HubError(
                f"cannot {action} {repo_id!r}: the Hub refused the token (HTTP {status})",
                hint="use a token with write access: `hf auth login` or HF_TOKEN",
            ) from exc
        raise HubError(
            f"cannot {action} {repo_id!r}: the Hub answered HTTP {status} ({exc})",
            hint="retry later; check the repo on the Hub",
        ) from exc
    except (OSError, ConnectionError, TimeoutError) as exc:
        raise unreachable(exc) from exc
    except Exception as exc:  # httpx errors and others that do not derive from OSError
        # huggingface_hub 2.x talks through httpx2/httpcore2, 1.x through httpx, older ones through requests
        if type(exc).__module__.split(".")[0].rstrip("0123456789") in {"httpx", "httpcore", "requests", "urllib"}:
            raise unreachable(exc) from exc
        raise


def _retry_hint(instead: str | None) -> str:
    """How to try again when the Hub could not be reached: the network, the offline switch, the endpoint, and for a
    publish (no ``instead``) the token; a pull adds what can be done without the Hub."""
    where = endpoint()
    text = "check the network and run the same command again, with HF_HUB_OFFLINE unset; " + (
        f"HF_ENDPOINT={where} is the Hub asked: check that it answers, or unset HF_ENDPOINT for https://huggingface.co"
        if where
        else "behind a proxy set HTTPS_PROXY, or point HF_ENDPOINT at a Hub mirror that is reachable"
    )
    if instead:
        return f"{text}; or {instead}"
    return f"{text}; the token used is HF_TOKEN's, else the one `hf auth login` saved"


def _token() -> str:
    from huggingface_hub import get_token

    token = get_token()
    if not token:
        raise HubError(
            "no Hugging Face token found, so nothing can be published",
            hint="run `hf auth login` or set HF_TOKEN to a token with write access",
        )
    return token


# --------------------------------------------------------------------------------------------------------- publish


@dataclass(frozen=True)
class PublishResult:
    repo_id: str
    tag: str | None
    version: str
    commit: str | None
    already_published: bool = False

    def describe(self) -> str:
        if self.already_published:
            return f"{self.repo_id}: version {self.version} is already published ({self.tag}); nothing to do"
        return f"published {self.version} as {self.tag} to {self.repo_id} (commit {self.commit})"


def publish_operations(vdir: Path, card_text: str) -> list[Any]:
    """The files of one commit: every data file of the version and its scene, plus the card as ``README.md``."""
    from huggingface_hub import CommitOperationAdd

    ops = [
        CommitOperationAdd(path_in_repo=f, path_or_fileobj=str(vdir / f))
        for f in version_files(vdir, local.read_meta(vdir))
    ]
    ops.append(CommitOperationAdd(path_in_repo=P.CARD_FILE, path_or_fileobj=card_text.encode()))
    return ops


def publish(
    name: str | DatasetId,
    revision: str | None = None,
    *,
    repo_id: str | None = None,
    private: bool = False,
    api: Any = None,
) -> PublishResult:
    """Upload one stored version (verified first) as one tagged commit; ``api`` replaces ``HfApi`` in tests."""
    if repo_id is not None:
        check_repo_id(repo_id)
    did, version, vdir = local.resolve(name, revision)
    repo_id = repo_id or default_repo(did)
    problems = local.verify_dir(vdir)
    if problems:
        raise CorruptDatasetError(
            f"refusing to publish damaged {did.name}@{version}: " + "; ".join(problems),
            hint="rebuild it first (`make dataset`)",
        )
    meta = local.read_meta(vdir)
    history = listing.history(did)
    upto = history[: next((i + 1 for i, (_, m) in enumerate(history) if m.get("version") == version), len(history))]
    tag = next((t for t, m in history if m.get("version") == version), None)
    card = render_version_card(meta, tag=tag, history=upto, hub_repo=repo_id)
    ops = publish_operations(vdir, card)

    def stale(api_) -> list[str]:  # e.g. paths.parquet, or a mesh of a material gone, of an older version
        ours = set(version_files(vdir, meta))
        return [
            f
            for f in api_.list_repo_files(repo_id, repo_type="dataset")
            if (f in DATA_FILES or f.startswith(f"{P.SCENE_DIR}/")) and f not in ours
        ]

    return push_version(
        repo_id, ops, name=did.name, tag=tag, version=version, what="dataset", private=private, api=api, stale=stale
    )


def push_version(
    repo_id: str,
    ops: list[Any],
    *,
    name: str,
    tag: str | None,
    version: str,
    what: str,
    private: bool,
    api: Any = None,
    stale=None,
) -> PublishResult:
    """Upload ``ops`` as one commit tagged with ``tag`` and ``version`` (both never moved); ``stale(api)`` names
    remote files to delete in the same commit. Shared by RT and logged datasets; ``api`` replaces ``HfApi`` in tests."""
    if offline():
        raise HubError(
            f"cannot publish to {repo_id!r}: offline mode is on (HF_HUB_OFFLINE=1)",
            hint="unset HF_HUB_OFFLINE on a machine with network access",
        )
    if api is None:
        from huggingface_hub import HfApi

        api = HfApi(endpoint=endpoint(), token=_token())
    with hub_errors("publish to", repo_id):
        api.create_repo(repo_id, repo_type="dataset", private=private, exist_ok=True)
        remote_tags = {t.name for t in api.list_repo_refs(repo_id, repo_type="dataset").tags}
        if version in remote_tags:
            return PublishResult(repo_id, tag, version, None, already_published=True)
        if tag in remote_tags:
            raise HubError(
                f"{repo_id!r} already has a tag {tag!r} for another version than {version}",
                hint="tags are never moved: publish to another --repo, or pull the Hub's versions "
                "first so local tags follow the Hub's",
            )
        if stale is not None:
            from huggingface_hub import CommitOperationDelete

            ops = [*ops, *(CommitOperationDelete(path_in_repo=f) for f in stale(api))]
        info = api.create_commit(
            repo_id,
            ops,
            commit_message=f"{name} {tag}: version {version}",
            commit_description=f"dtradar {what} {name}, content version {version}",
            repo_type="dataset",
        )
        for name_ in (tag, version):
            if name_:
                api.create_tag(
                    repo_id, tag=name_, revision=info.oid, repo_type="dataset", tag_message=f"{name} version {version}"
                )
    return PublishResult(repo_id, tag, version, info.oid)


# ------------------------------------------------------------------------------------------------------------ pull


def download(repo_id: str, revision: str, dest: Path, cache: Path, *, files: list[str]) -> Path:
    """The only download call, for both kinds of dataset: the ``files`` of ``repo_id`` at ``revision`` into
    ``dest`` (the Hub endpoint and offline mode from the environment)."""
    from huggingface_hub import snapshot_download

    return Path(
        snapshot_download(
            repo_id,
            repo_type="dataset",
            revision=revision,
            local_dir=dest,
            cache_dir=cache,
            endpoint=endpoint(),
            local_files_only=offline(),
            allow_patterns=list(files),
        )
    )


def _download(repo_id: str, revision: str, dest: Path, cache: Path) -> Path:
    """An RT dataset's files; a separate function so tests can replace the network with a local folder."""
    return download(repo_id, revision, dest, cache, files=[*DATA_FILES, P.CARD_FILE, SCENE_PATTERN])


def _remote_revision(repo_id: str, revision: str | None, instead: str | None = None) -> str:
    """A Hub revision for ``revision``: tags and full hashes are Hub tags; a short hash prefix is expanded."""
    if revision is None:
        return "main"
    if is_tag(revision) or not is_hash(revision) or len(revision) >= 16:
        return revision
    from huggingface_hub import HfApi

    with hub_errors("look up revisions of", repo_id, what=revision, instead=instead):
        tags = [t.name for t in HfApi(endpoint=endpoint()).list_repo_refs(repo_id, repo_type="dataset").tags]
    matches = [t for t in tags if is_hash(t) and t.startswith(revision)]
    if len(matches) != 1:
        raise HubError(
            f"{repo_id!r} has {len(matches)} versions starting with {revision!r}",
            hint=f"give a tag or at least {MIN_HASH_PREFIX}+ distinct characters of the hash",
        )
    return matches[0]


def _card_tag(readme: Path) -> str | None:
    """The tag the publisher gave this version (``dtradar.tag`` in the card's YAML), to keep it locally."""
    if not readme.is_file():
        return None
    import yaml
    from huggingface_hub import DatasetCard

    try:
        tag = (DatasetCard.load(readme).data.to_dict().get("dtradar") or {}).get("tag")
    except (ValueError, TypeError, AttributeError, OSError, yaml.YAMLError):
        return None  # a hand-edited card must not block a verified download; fall back to the next free tag
    return tag if isinstance(tag, str) and is_tag(tag) else None


@dataclass(frozen=True)
class PullResult:
    """What a pull did. ``downloaded`` is False when the revision asked for was already in the local store (the Hub
    was not asked); ``installed`` is False when a download brought a version the store already held."""

    name: str
    path: Path
    version: str
    tag: str | None
    repo_id: str
    asked: str | None
    downloaded: bool
    installed: bool

    def describe(self) -> str:
        here = f"{self.name}@{self.tag or self.version}"
        if not self.downloaded:
            return (
                f"nothing downloaded: {self.name}@{self.asked} is already in the local store ({self.path}), so the "
                f"Hub was not asked; `python -m dtradar_data verify {self.name}@{self.asked}` checks it, and a pull "
                "downloads it again once that folder is removed"
            )
        if not self.installed:
            return (
                f"downloaded {here} from {self.repo_id}: version {self.version} was already in the local store "
                f"({self.path}); nothing changed"
            )
        return f"pulled {here} (version {self.version}) from {self.repo_id} into {self.path}"


def _tag_of(did: DatasetId, version: str) -> str | None:
    return read_refs(P.refs_path(did.scene, did.variant)).tag_of(version)


def _without_the_hub(did: DatasetId) -> str:
    """What a pull's user can do without the Hub: use the copy already here (named), or build it (the command)."""
    try:
        _, version, vdir = local.resolve(did.with_revision(None))
    except DtradarError:
        return f"build it locally with {build_command(did)}"
    tag = _tag_of(did, version)
    return f"use the copy already here: {did.name}@{tag or version} ({vdir}) is its newest version in the local store"


def pull(name: str | DatasetId, revision: str | None = None, *, repo_id: str | None = None) -> Path:
    """Make ``name@revision`` available locally: return it if present, else download, verify and install it."""
    return pull_version(name, revision, repo_id=repo_id).path


def pull_version(name: str | DatasetId, revision: str | None = None, *, repo_id: str | None = None) -> PullResult:
    """:func:`pull`, saying what it did (:meth:`PullResult.describe`: downloaded, or nothing downloaded and why)."""
    if repo_id is not None:
        check_repo_id(repo_id)
    # With an explicit repo any well-formed name may be pulled (e.g. a scene this checkout has no file for).
    did = name if isinstance(name, DatasetId) else as_id(name, check_known=repo_id is None)
    missing = missing_twin(did) if repo_id is None else None
    if missing is not None:  # a variant its scene does not have: no default repo can hold it
        raise missing
    revision = revision or did.revision
    did, repo_id = did.with_revision(None), repo_id or default_repo(did)
    if revision is not None:
        with contextlib.suppress(DatasetNotFoundError, RevisionNotFoundError):
            _, version, vdir = local.resolve(did, revision)
            return PullResult(did.name, vdir, version, _tag_of(did, version), repo_id, revision, False, False)
    writing.clean_stages()
    instead = _without_the_hub(did)
    # held: a pull killed mid-download leaves its stage to the next pull or build, never one still downloading
    with held_stage(P.work_root(), writing.stage_prefix(did)) as stage:
        with hub_errors("pull from", repo_id, what=revision and f"{did.name}@{revision}", instead=instead):
            # Offline, the real (local-files-only) download call still runs: the library's own check answers.
            remote = _remote_revision(repo_id, revision, instead) if not offline() else (revision or "main")
            got = _download(repo_id, remote, stage / "download", stage / "cache")
        version_dir = stage / "version"
        version_dir.mkdir()
        meta = local.read_meta(got)
        existed = bool(HASH_RE.fullmatch(str(meta.get("version", "")))) and local.version_exists(did, meta["version"])
        for fname in [*(meta.get("files") or {}), P.META_FILE, P.CARD_FILE]:
            # a plain name or the scene folder's, never a path out of the version (verify_dir then finds it missing)
            if (got / fname).is_file() and (Path(fname).name == fname or P.is_scene_file(fname)):
                (version_dir / fname).parent.mkdir(parents=True, exist_ok=True)
                shutil.move(str(got / fname), version_dir / fname)
        preferred = revision if revision and is_tag(revision) else _card_tag(version_dir / P.CARD_FILE)
        path = writing.install_staged(did, version_dir, preferred_tag=preferred)
    return PullResult(did.name, path, path.name, _tag_of(did, path.name), repo_id, revision, True, not existed)
