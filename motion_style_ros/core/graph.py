"""The canonical skeleton as a graph for spatial-temporal graph convolution (ST-GCN), in numpy.

Nodes are the joints that :func:`~motion_style_ros.core.features.feature_layout` describes (the
pelvis and its descendants), in that order. Each node's neighbourhood is partitioned as in ST-GCN
(Yan et al. 2018, Park et al. 2021): the node itself, its neighbour closer to the root (its
parent) and its neighbours farther from it (its children), one normalised adjacency matrix per
subset. Graph pooling averages clusters of consecutive joints inside one body part; two levels
take the 21 nodes to 11 and then to the 5 body parts.

:func:`node_scatter` lays encode() features out per node (``(..., N, C)``) by a fixed 0/1 matrix,
so decoding stays the one in ``core.features``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion_style_ros.core.features import feature_layout
from motion_style_ros.core.skeleton import Skeleton, canonical

PARTITIONS = 3  # self, closer to the root, farther from it
# Channels per node: rot6d (6), position (3), velocity (3), then the root block (4: forward-plane
# velocity, pelvis height, yaw rate) on the pelvis node only and the foot contact on the four
# contact joints only (zero elsewhere).
NODE_CHANNELS = {"rot6d": slice(0, 6), "pos": slice(6, 9), "vel": slice(9, 12),
                 "root": slice(12, 16), "contact": slice(16, 17)}
MOTION_CHANNELS = 16  # without the contact channel
ALL_CHANNELS = 17


@dataclass(frozen=True)
class Graph:
    """A tree of ``n`` nodes (``parents[0] == -1``: the root) and how it pools into the next level."""

    parents: tuple[int, ...]

    @property
    def n(self) -> int:
        return len(self.parents)

    def adjacency(self) -> np.ndarray:
        """``(3, n, n)`` float32: self, closer (parent), farther (children); each subset's row
        normalised by its size (the 1/Z term), so a node averages its children."""
        a = np.zeros((PARTITIONS, self.n, self.n), dtype=np.float32)
        a[0] = np.eye(self.n)
        for child, parent in enumerate(self.parents):
            if parent >= 0:
                a[1, child, parent] = 1.0
                a[2, parent, child] = 1.0
        rows = a[2].sum(axis=1, keepdims=True)
        a[2] = np.divide(a[2], rows, out=np.zeros_like(a[2]), where=rows > 0)
        return a


def skeleton_graph(skeleton: Skeleton | None = None) -> Graph:
    """The feature joints of ``skeleton`` (default canonical) as a graph rooted at the pelvis."""
    sk = skeleton or canonical()
    joints = feature_layout(sk).joints
    return Graph(tuple(joints.index(sk.parents[j]) if k else -1 for k, j in enumerate(joints)))


def _pair_from_tip(chain: list[int]) -> list[list[int]]:
    """Consecutive pairs of a root-to-tip chain, paired from the tip (an odd root-most node stays
    alone, so the pelvis keeps a cluster of its own)."""
    groups = [chain[max(0, i - 1) : i + 1] for i in range(len(chain) - 1, -1, -2)]
    return groups[::-1]


def pool_clusters(skeleton: Skeleton | None = None) -> list[list[list[int]]]:
    """Clusters of each pooling step, as lists of node indices of the level below: step 1 pairs
    consecutive joints inside each body part (21 -> 11 nodes), step 2 merges each body part into
    one node (11 -> 5). Clusters are ordered so that every cluster's parent comes first."""
    sk = skeleton or canonical()
    joints = feature_layout(sk).joints
    parts = [[joints.index(j) for j in part] for part in sk.parts.values()]
    parts.sort(key=min)
    fine = [g for part in parts for g in _pair_from_tip(part)]
    coarse = [[fine.index(g) for g in _pair_from_tip(part)] for part in parts]
    return [fine, coarse]


def pooled_graph(graph: Graph, clusters: list[list[int]]) -> Graph:
    """The graph of the clusters: a cluster's parent holds the parent of its root-most node."""
    owner = {node: c for c, members in enumerate(clusters) for node in members}
    parents = []
    for members in clusters:
        top = min(members)  # nodes follow their parents, so the smallest is the root-most
        parents.append(-1 if graph.parents[top] < 0 else owner[graph.parents[top]])
    return Graph(tuple(parents))


def pool_matrix(n: int, clusters: list[list[int]]) -> np.ndarray:
    """``(n, clusters)`` float32: ``x @ P`` averages each cluster's nodes; ``y @ (P > 0).T``
    copies each cluster back onto its nodes (unpooling)."""
    p = np.zeros((n, len(clusters)), dtype=np.float32)
    for c, members in enumerate(clusters):
        p[members, c] = 1.0 / len(members)
    return p


def hierarchy(skeleton: Skeleton | None = None) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Adjacency ``(3, n, n)`` of each level (21, 11, 5 nodes) and the pooling matrices between
    consecutive levels."""
    graph = skeleton_graph(skeleton)
    adjacency, pools = [graph.adjacency()], []
    for clusters in pool_clusters(skeleton):
        pools.append(pool_matrix(graph.n, clusters))
        graph = pooled_graph(graph, clusters)
        adjacency.append(graph.adjacency())
    return adjacency, pools


def node_scatter(skeleton: Skeleton | None = None) -> np.ndarray:
    """``(F, N * 17)`` float32 0/1 matrix: ``features @ M``, reshaped to ``(..., N, 17)``, lays
    encode() features out per node (``NODE_CHANNELS``); one matrix product, so exported networks
    compute the layout themselves from raw features."""
    sk = skeleton or canonical()
    lay = feature_layout(sk)
    n = len(lay.joints)
    m = np.zeros((lay.size, n * ALL_CHANNELS), dtype=np.float32)

    def put(block: slice, nodes: list[int], channels: slice) -> None:
        dest = np.array(nodes)[:, None] * ALL_CHANNELS + np.arange(channels.start, channels.stop)
        m[np.arange(block.start, block.stop), dest.ravel()] = 1.0

    for name in ("rot6d", "pos", "vel"):
        put(lay.slices[name], list(range(n)), NODE_CHANNELS[name])
    put(lay.slices["root"], [0], NODE_CHANNELS["root"])
    put(lay.slices["contact"], [lay.joints.index(j) for j in sk.feet], NODE_CHANNELS["contact"])
    return m
