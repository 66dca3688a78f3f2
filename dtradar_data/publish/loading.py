"""``dtradar_data.load``: the local store first, then, when asked, the Hugging Face Hub."""

from __future__ import annotations

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DatasetNotFoundError, RevisionNotFoundError
from dtradar_data.core.ids import DatasetId
from dtradar_data.publish import hub, logged_hub
from dtradar_data.store import local
from dtradar_data.store.logged import LoggedDataset, is_logged_name, load_logged


def load(
    name: str | DatasetId,
    revision: str | None = None,
    *,
    paths: bool = False,
    verify: bool = True,
    from_hub: bool = False,
    repo_id: str | None = None,
) -> Dataset | LoggedDataset:
    """Load a dataset version: the newest without ``revision`` (or ``@rev`` in ``name``), else a tag or hash.

    ``paths=True`` also reads the per-path table into ``Dataset.paths_table``; ``verify`` re-hashes the files read
    against ``meta.json``. ``from_hub=True`` pulls the revision from the Hugging Face Hub when it is not in the local
    store (see :func:`dtradar_data.publish.hub.pull`).

    A logged offline-RL dataset, ``scene/variant/behaviour[@revision]``, returns a
    :class:`~dtradar_data.store.logged.LoggedDataset` (``from_hub`` as above, see
    :mod:`dtradar_data.publish.logged_hub`).
    """
    if is_logged_name(name):
        try:
            return load_logged(name, revision, verify=verify)
        except (DatasetNotFoundError, RevisionNotFoundError):
            if not from_hub:
                raise
        logged_hub.pull(name, revision, repo_id=repo_id)
        return load_logged(name, revision, verify=verify)
    try:
        return local.load(name, revision, paths=paths, verify=verify)
    except (DatasetNotFoundError, RevisionNotFoundError):
        if not from_hub:
            raise
    hub.pull(name, revision, repo_id=repo_id)
    return local.load(name, revision, paths=paths, verify=verify)
