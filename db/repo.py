"""Repository: the functions the rest of railval calls to read and write the database, in one
namespace (``from railval.db import repo; repo.load_signalsets(...)``).

They live by concept in :mod:`railval.db.campaigns` (references, campaign and configuration
lookups, summaries), :mod:`railval.db.signals` (reading and adding signals, content hashes),
:mod:`railval.db.configurations` (storing and deleting configurations),
:mod:`railval.db.seals` (seals and content hashes checked) and :mod:`railval.db.cache` (the
result cache); this module re-exports them.

All functions take an open :class:`sqlalchemy.orm.Session` (from
:meth:`railval.db.engine.Database.session`, which commits or rolls back the unit of work). A
request resolves its campaign and configuration once at its entrance (:func:`resolve`,
docs/design.md §2) and passes the :class:`CampaignRef` / :class:`ConfigRef` on; the functions
also take a campaign's row, name or id and a configuration's name
(:data:`CampaignArg`, :data:`ConfigArg`), looked up on every call.
"""

from __future__ import annotations

from railval.db.cache import (
    CACHE_CHUNK,
    cache_delete,
    cache_get,
    cache_get_many,
    cache_put,
    cache_put_many,
)
from railval.db.campaigns import (
    CampaignArg,
    CampaignRef,
    ConfigArg,
    ConfigRef,
    campaign_id,
    campaign_ref,
    campaign_summary,
    catalogue_stamp,
    channels,
    check_campaign_name,
    config_name,
    count_signals,
    delete_campaign,
    get_campaign,
    get_configuration,
    is_campaign_id,
    lineage,
    list_campaigns,
    list_configurations,
    resolve,
    row_counts,
    section_infos,
    section_layouts,
    vehicle_info,
)
from railval.db.configurations import (
    _jsonable,
    check_new_configuration,
    configuration_state,
    delete_configuration,
    store_configuration,
)
from railval.db.seals import (
    hash_rows_many,
    raise_problems,
    require_sealed,
    require_sealed_many,
    seal_problems,
    seal_rows_many,
    verify_seals,
    verify_signals,
    verify_storage,
)
from railval.db.signals import (
    add_recordings,
    fetch_signalsets,
    load_signalsets,
    recording_meta,
    signal_hashes,
    source_filter,
    source_hashes,
    stored_blobs,
)

__all__ = [
    "CACHE_CHUNK",
    "CampaignArg",
    "CampaignRef",
    "ConfigArg",
    "ConfigRef",
    "_jsonable",
    "add_recordings",
    "cache_delete",
    "cache_get",
    "cache_get_many",
    "cache_put",
    "cache_put_many",
    "campaign_id",
    "campaign_ref",
    "campaign_summary",
    "channels",
    "check_campaign_name",
    "catalogue_stamp",
    "check_new_configuration",
    "config_name",
    "configuration_state",
    "count_signals",
    "delete_campaign",
    "delete_configuration",
    "fetch_signalsets",
    "get_campaign",
    "get_configuration",
    "is_campaign_id",
    "hash_rows_many",
    "lineage",
    "list_campaigns",
    "list_configurations",
    "load_signalsets",
    "raise_problems",
    "recording_meta",
    "require_sealed",
    "require_sealed_many",
    "resolve",
    "row_counts",
    "seal_problems",
    "seal_rows_many",
    "section_infos",
    "section_layouts",
    "signal_hashes",
    "source_filter",
    "source_hashes",
    "store_configuration",
    "stored_blobs",
    "vehicle_info",
    "verify_seals",
    "verify_signals",
    "verify_storage",
]
