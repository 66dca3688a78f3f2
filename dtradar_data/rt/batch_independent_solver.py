"""The batch-independent PathSolver: Sionna 2.2's solver with the receivers of a call decoupled.

:class:`BatchIndependentPathSolver` is what :class:`~dtradar_data.rt.tracer.RayTracer` traces with under
``--rt.batch-independent`` (the default): a receiver's paths are then the same bytes whatever else is traced in the
same call. The tracer's module doc says how Sionna couples the receivers of a call and what each change removes; in
short, each receiver has its own region of :data:`HASH_SLOTS_PER_RX` slots in the specular-chain tables
(:class:`BatchIndependentCandidateGenerator`), each receiver's candidates fill whole SIMD packets of :data:`_PACKET`
lanes of their own in the image method, and a call whose path buffer filled says so (:attr:`buffer_full`).

The two overridden methods copy sionna-rt 2.2.0 (Apache-2.0, NVIDIA) apart from the lines marked CHANGED, so this
module fits only the releases in :data:`~dtradar_data.rt.sionna_version.PATCHED_SIONNA_RT_VERSIONS`: the tracer
checks the installed one (:func:`~dtradar_data.rt.sionna_version.check_patched_sionna_rt`) before it imports this
module. Import it only after :func:`dtradar_data.rt.tracer._import_sionna` has configured LLVM and picked the
Mitsuba variant (importing Sionna first would pick a variant of its own); the tracer does both.
"""

from __future__ import annotations

# @dr.syntax recompiles the shoot-and-bounce loop from its source without its closure: every name it uses must be
# a global of this module (and a test monkeypatches HASH_SLOTS_PER_RX here, read at each call)
import drjit as dr
import mitsuba as mi
import numpy as np
import sionna.rt as rt
from sionna.rt.constants import InteractionType
from sionna.rt.path_solvers.paths import Paths
from sionna.rt.path_solvers.sample_data import SampleData
from sionna.rt.path_solvers.sb_candidate_generator import SBCandidateGenerator
from sionna.rt.utils import fibonacci_lattice, hash_fnv1a, spawn_ray_from_sources

__all__ = ["HASH_SLOTS_PER_RX", "BatchIndependentCandidateGenerator", "BatchIndependentPathSolver"]

HASH_SLOTS_PER_RX = 1 << 16
"""Slots of each receiver's region of the specular-chain tables (two tables of 4-byte counters: 512 KiB per
receiver). A chain whose slot holds another of the same receiver's chains is still lost, but the same way in any
call; the cubicle at 1e4 samples has ~1 000 candidate chains per receiver. Changing it changes results."""
_PACKET = 32  # lanes per receiver group in the image method: a multiple of every LLVM/CUDA packet width


class BatchIndependentCandidateGenerator(SBCandidateGenerator):
    """Sionna's shoot-and-bounce candidate generator with one region of the specular-chain tables per receiver."""

    @dr.syntax
    def _shoot_and_bounce_loop(
        self,
        mi_scene,
        src_positions,
        tgt_positions,
        samples_per_src,
        max_num_paths_per_src,
        max_depth,
        paths,
        paths_counter_per_source,
        specular_reflection_enabled,
        diffuse_reflection_enabled,
        refraction_enabled,
        diffraction_enabled,
        edge_diffraction_enabled,
        sampler,
        src_boxes=None,
    ):
        num_sources = dr.shape(src_positions)[1]
        num_targets = dr.shape(tgt_positions)[1]
        num_samples = samples_per_src * num_sources
        samples_data = SampleData(num_sources, samples_per_src, max_depth, diffraction_enabled)
        ray = spawn_ray_from_sources(fibonacci_lattice, samples_per_src, src_positions)
        if dr.hint(src_boxes is not None, mode="scalar"):
            ray.o, _ = src_boxes.advance(ray.o, ray.d, samples_data.src_indices)
        k_tx = dr.copy(ray.d)
        specular_chain = dr.full(mi.Bool, True, num_samples)
        num_hashes = len(self.plane_hash_functions)
        hashes = [dr.zeros(mi.UInt64, num_samples) for _ in range(num_hashes)]
        region = HASH_SLOTS_PER_RX
        spec_counter_size = region * num_targets  # CHANGED: one region per target (was max(max paths, 1e6))
        specular_chain_counters = [dr.zeros(mi.UInt, spec_counter_size * num_sources) for _ in range(num_hashes)]
        depth = dr.full(mi.UInt, 1, num_samples)
        active = dr.full(mi.Mask, True, num_samples)
        loc_en_inter = dr.full(mi.UInt, 0, num_samples)
        if specular_reflection_enabled:
            loc_en_inter |= InteractionType.SPECULAR
        if diffuse_reflection_enabled:
            loc_en_inter |= InteractionType.DIFFUSE
        if refraction_enabled:
            loc_en_inter |= InteractionType.REFRACTION
        if diffraction_enabled:
            loc_en_inter |= InteractionType.DIFFRACTION
        counters, per_src = specular_chain_counters, paths_counter_per_source
        while dr.hint(active, label="shoot_and_bounce", exclude=[counters, per_src]):
            si_scene = mi_scene.ray_intersect(ray, coherent=True, ray_flags=mi.RayFlags.Minimal, active=active)
            active &= si_scene.is_valid()
            sample1 = sampler.next_1d()
            sample2 = sampler.next_2d()
            sample2_diffraction = sampler.next_2d()
            s, n, wedges = self._sample_radio_material(
                si_scene,
                ray.o,
                ray.d,
                sample1,
                sample2,
                sample2_diffraction,
                loc_en_inter,
                diffraction_enabled,
                edge_diffraction_enabled,
                active,
            )
            k_world = s.wo
            int_type = dr.select(active, s.sampled_component, InteractionType.NONE)
            active &= int_type != InteractionType.NONE
            specular = int_type == InteractionType.SPECULAR
            transmission = int_type == InteractionType.REFRACTION
            diffuse = int_type == InteractionType.DIFFUSE
            diffraction = int_type == InteractionType.DIFFRACTION
            loc_en_inter[diffraction] &= ~(mi.UInt(InteractionType.DIFFUSE + InteractionType.DIFFRACTION))
            loc_en_inter[diffuse] &= ~mi.UInt(InteractionType.DIFFRACTION)
            specular_chain &= active & (specular | transmission | diffraction)
            samples_data.insert(depth, int_type, si_scene.shape, si_scene.prim_index, wedges, si_scene.p, s.pdf, active)
            for i in range(num_hashes):
                plane_hash = self.plane_hash_functions[i](si_scene.n, si_scene.p)
                edge_hash = self.edge_hash_functions[i](wedges.o, wedges.o + wedges.e_hat * wedges.length)
                inter_hash = dr.select(int_type == InteractionType.SPECULAR, plane_hash, int_type)
                inter_hash = dr.select(int_type == InteractionType.DIFFRACTION, edge_hash, inter_hash)
                hashes[i] = hash_fnv1a(inter_hash, h=hashes[i])
            t = mi.UInt(0)
            while dr.hint(t < num_targets, label="shoot_and_bounce_inner", exclude=[counters, per_src]):
                tgt_position = dr.gather(mi.Point3f, tgt_positions, t)
                los_ray = si_scene.spawn_ray_to(tgt_position)
                los_blocked = mi_scene.ray_test(los_ray, active=active)
                los_visible = ~los_blocked
                target_incident_side = dr.dot(n, los_ray.d) > 0.0
                valid = los_visible & diffuse & target_incident_side
                new_specular = specular_chain & los_visible
                for i in range(num_hashes):
                    # CHANGED: the slot lies in target t's own region, at a place given by the chain alone
                    # (was hash_fnv1a(t, h) % spec_counter_size, shared by all targets)
                    h = hashes[i]
                    counter_ind = mi.UInt((h ^ (h >> 32)) % region) + region * t
                    counter_ind += spec_counter_size * samples_data.src_indices
                    samples_counter = dr.scatter_inc(counters[i], counter_ind, new_specular)
                    new_specular &= samples_counter == 0
                store = active & (valid | new_specular)
                num_path_per_src = dr.scatter_inc(per_src, samples_data.src_indices, store)
                store &= num_path_per_src < max_num_paths_per_src
                path_ind = dr.scatter_inc(paths.paths_counter, mi.UInt(0), store)
                paths.add_paths(depth, path_ind, samples_data, valid, t, k_tx, -los_ray.d, store)
                t += 1
            depth += 1
            active &= depth <= max_depth
            ray = si_scene.spawn_ray(d=k_world)
            specular_chain |= diffuse


class BatchIndependentPathSolver(rt.PathSolver):
    """Sionna's PathSolver with the receivers of a call decoupled: its own candidate generator, each receiver's
    candidates in whole packets of their own, and :attr:`buffer_full` reporting a call whose path buffer filled."""

    def __init__(self):
        super().__init__(deterministic=False)
        self._candidate_generator = BatchIndependentCandidateGenerator()
        self.buffer_full = False  # whether the last call's candidate buffer filled

    def __call__(
        self,
        scene,
        max_depth=3,
        max_num_paths_per_src=1000000,
        samples_per_src=1000000,
        synthetic_array=True,
        los=True,
        specular_reflection=True,
        diffuse_reflection=False,
        refraction=True,
        diffraction=False,
        edge_diffraction=False,
        diffraction_lit_region=True,
        seed=42,
    ):
        scene.all_set(radio_map=False)
        src_positions, src_orientations, rel_ant_tx, tx_velocities = scene.sources(synthetic_array, True)
        tgt_positions, tgt_orientations, rel_ant_rx, rx_velocities = scene.targets(synthetic_array, True)
        dr.make_opaque(src_positions, tgt_positions, src_orientations, tgt_orientations)
        buf = self._candidate_generator(
            mi_scene=scene.mi_scene,
            src_positions=src_positions,
            tgt_positions=tgt_positions,
            samples_per_src=samples_per_src,
            max_num_paths_per_src=max_num_paths_per_src,
            max_depth=max_depth,
            los=los,
            specular_reflection=specular_reflection,
            diffuse_reflection=diffuse_reflection,
            refraction=refraction,
            diffraction=diffraction,
            edge_diffraction=edge_diffraction,
            seed=seed,
        )
        buf.schedule()
        dr.eval()
        # CHANGED: report a full buffer (the call's receivers then competed for its places)
        self.buffer_full = int(dr.max(buf.paths_counter)[0]) >= max_num_paths_per_src * dr.width(src_positions)
        buf.shrink()
        buf.detach_geometry()
        # CHANGED: each (target, source) pair's candidates fill whole packets of their own, in their order
        buf, padding = _packed(buf)
        buf = self._image_method(
            scene=scene.mi_scene,
            paths=buf,
            src_positions=src_positions,
            tgt_positions=tgt_positions,
            diffraction=diffraction,
            diffraction_lit_region=diffraction_lit_region,
        )
        buf = self._field_calculator(
            wavelength=scene.wavelength,
            paths=buf,
            samples_per_src=samples_per_src,
            diffraction=diffraction,
            src_positions=src_positions,
            tgt_positions=tgt_positions,
            src_orientations=src_orientations,
            tgt_orientations=tgt_orientations,
            src_antenna_patterns=scene.tx_array.antenna_pattern.patterns,
            tgt_antenna_patterns=scene.rx_array.antenna_pattern.patterns,
        )
        buf.valid = buf.valid & ~padding  # CHANGED: drop the padding copies
        buf.discard_invalid()
        return Paths(
            scene,
            src_positions,
            tgt_positions,
            tx_velocities,
            rx_velocities,
            synthetic_array,
            buf,
            rel_ant_tx,
            rel_ant_rx,
        )


def _packed(buf):
    """``buf`` reordered so that each (target, source) pair's candidates, in their original order, start on a
    multiple of :data:`_PACKET` lanes, padded with copies of the pair's last candidate; and the padding mask."""
    n = buf.buffer_size
    if n == 0:
        return buf, mi.Bool(np.zeros(0, bool))
    tgt = np.asarray(buf.target_indices, dtype=np.int64)[:n]
    src = np.asarray(buf.source_indices, dtype=np.int64)[:n]
    key = tgt * (int(src.max()) + 1) + src
    order = np.argsort(key, kind="stable")
    starts = np.flatnonzero(np.r_[True, key[order][1:] != key[order][:-1]])
    counts = np.diff(np.r_[starts, n])
    slots = -(-counts // _PACKET) * _PACKET
    first = np.r_[0, np.cumsum(slots)[:-1]]  # where each pair's group starts in the packed buffer
    lane = np.arange(int(slots.sum())) - np.repeat(first, slots)  # position within its group
    group = np.repeat(np.arange(len(starts)), slots)
    padding = lane >= counts[group]
    index = order[np.repeat(starts, slots) + np.minimum(lane, counts[group] - 1)]
    return buf.gather(mi.UInt(index.astype(np.uint32))), mi.Bool(padding)
