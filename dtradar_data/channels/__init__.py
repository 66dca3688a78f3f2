"""Channels of any antenna array pair from a stored dataset's per-path table (DeepMIMO's workflow): see
:class:`ChannelGenerator`; the table needs the channel columns (``--rt.path-channels``)."""

from dtradar_data.channels.arrays import Array
from dtradar_data.channels.generator import ChannelGenerator, Channels, ofdm_frequencies
from dtradar_data.channels.stored import StoredPaths

__all__ = ["Array", "ChannelGenerator", "Channels", "StoredPaths", "ofdm_frequencies"]
