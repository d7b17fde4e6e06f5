"""Configuration of the SfM stage (``curate.sfm.colmap.run_sfm``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

Matcher = Literal["auto", "exhaustive", "sequential", "spatial", "retrieval"]
MATCHERS = get_args(Matcher)
"""``SfmConfig.matcher`` choices. The visual words (``sequential``'s loop detection, ``retrieval``) are
learned from the capture itself (:mod:`curate.sfm.retrieval`): COLMAP's published trees are downloads."""
CameraMode = Literal["auto", "single", "per_image"]
CAMERA_MODES = get_args(CameraMode)
"""``SfmConfig.camera_mode`` choices."""
OnSplit = Literal["largest", "each", "stop"]
ON_SPLIT = get_args(OnSplit)
"""``SfmConfig.on_split`` choices."""
Mapper = Literal["auto", "incremental", "global"]
MAPPERS = get_args(Mapper)
"""``SfmConfig.mapper`` choices."""
Guided = Literal["auto", "on", "off"]
GUIDED = get_args(Guided)
"""``SfmConfig.guided_matching`` choices."""
AutoOff = Literal["auto", "off"]
TRIANGULATE = get_args(AutoOff)
"""``SfmConfig.triangulate`` choices."""
MIN_PART = 10
"""``on_split = 'each'``: the fewest registered photos a part needs to be curated on its own."""
RETRIEVAL_REMATCH_BELOW = 0.9
"""Retrieval matching: a model holding under this share of the photos sends the photos it left out to a
second round of retrieval (``SfmConfig.retrieval_rematch_num_images``) and the capture is mapped again."""
TAKE_MIN_FRACTION = 0.1
"""A take (a video, or the photos of one folder) of a capture of several takes with under this share of
its frames in the model curate uses did not join the other takes: the SfM stage says so by name."""


VIDEO_EXTS = {".mp4", ".mov", ".m4v", ".mkv", ".avi", ".webm"}
"""File extensions read as videos (:mod:`curate.sfm.video`)."""


@dataclass(frozen=True)
class VideoConfig:
    """How candidate frames are chosen from a video."""

    max_frames: int = 1000
    """Most candidate frames per video (keeps SfM bounded: matching and mapping grow with the pool);
    at least 2, checked when there is a video."""
    change_step: float = 0.04
    """A window closes when the view has changed this much since it opened (mean absolute grey
    difference between consecutive thumbnails, 0..1, summed); raised until ``max_frames`` holds."""
    static_change: float = 0.004
    """Consecutive frames that differ less than this count as the same view (the walker stood still)."""
    analysis_side: int = 160
    """Longer side of the grey thumbnails the change is measured on (pixels)."""
    sharpness_side: int = 480
    """Longer side of the grey image the sharpness is measured on (pixels)."""

    def __post_init__(self) -> None:
        # max_frames (the user's --max-frames) is checked when there is a video to read
        # (curate.sfm.video.check_options), so that a run without one never fails on it
        if not (0 < self.change_step <= 1):
            raise ValueError(f"VideoConfig.change_step must be in (0, 1], got {self.change_step!r}")
        if not (0 <= self.static_change < 1):
            raise ValueError(f"VideoConfig.static_change must be in [0, 1), got {self.static_change!r}")
        if self.analysis_side < 16 or self.sharpness_side < 16:
            raise ValueError("VideoConfig.analysis_side and sharpness_side must be >= 16")



@dataclass
class SfmConfig:
    """Options of the SfM stage. Every field but ``num_threads`` and ``progress`` is part of the stage key."""

    # --- ingest
    max_image_size: int = 1600
    """Longer side, in pixels, of the working copies SfM reads."""
    recursive: bool = False
    """Also take photos from sub-folders."""
    # --- quality (curate.sfm.quality)
    drop_duplicates: bool = True
    """Drop near-identical photos (perceptual hash distance <= dup_max_distance)."""
    dup_max_distance: int = 4
    """Photos whose perceptual hashes differ in at most this many of their 256 bits are near-identical; consecutive
    video frames differ by >= ~12."""
    drop_blurry: bool = False
    """Drop blurry photos (sharpness far under the pool's median) instead of only flagging them."""
    blur_fraction: float = 0.3
    """Blurry threshold, relative to the pool's median sharpness."""
    # --- features
    camera_mode: CameraMode = "auto"
    """One camera for all photos (single) or one per photo (per_image); auto: single when every photo comes from one
    camera model at one size."""
    camera_model: str = "SIMPLE_RADIAL"
    """COLMAP model (f, cx, cy, k). RADIAL / OPENCV over-fit small object rings: templering at 480 px registers 4 of
    47 with RADIAL, 46 with SIMPLE_RADIAL."""
    max_num_features: int = 8192
    """SIFT features per image."""
    sift_peak_threshold: float = 0.02 / 3
    """SIFT's peak threshold (COLMAP's default); lower finds more features."""
    sift_upsample_below: int = 1000
    """SIFT starts from the working copy doubled (COLMAP's first octave -1) where its longer side is under this many
    pixels; a larger copy is first read as it is (first octave 0), and read again doubled where that gives too few
    features (a plain or dark photo). The doubled octave is about three quarters of the extraction's work, and its
    many small features most of the matching's. 0: every photo is tried undoubled first; more than --max-size: every
    photo is doubled, as COLMAP does."""
    sift_min_features_undoubled: int = 1024
    """A photo read undoubled (``sift_upsample_below``) keeps those features where it has at least this many; else
    it is read again doubled (the skull's plain photos: 640 undoubled, 2,632 doubled)."""
    # --- matching
    matcher: Matcher = "auto"
    """Which photo pairs to match: exhaustive (all), sequential (each frame with the next ones, and loops), spatial
    (by GPS), or auto: exhaustive for a small set, else spatial with GPS, sequential for video frames or numbered
    photos, retrieval otherwise; retrieval: each photo with its most similar photos (visual words learned from the
    capture itself, not a download)."""
    exhaustive_max_images: int = 150
    """'auto': exhaustive up to this many photos."""
    retrieval_num_images: int = 30
    """Retrieval: match each photo with its N most similar photos (pairs grow as photos x N, where exhaustive grows
    as photos^2 / 2)."""
    retrieval_rematch_num_images: int = 120
    """Retrieval: when the model leaves over 10% of the photos out, those are matched again with their N most similar
    photos and the capture mapped again (skull at N = 10: 28 of 66 photos after the first round)."""
    sequential_overlap: int = 15
    """Sequential: N neighbours of each frame i, after it: with ``sequential_quadratic`` (the default) the frames
    i + 1, i + 2, i + 4, ... i + 2^(N-1) (COLMAP 4's pairing: these replace the next N, they are not added to
    them); without it the next N frames."""
    sequential_quadratic: bool = True
    """Sequential: the neighbours at i + 2^k rather than the next ``sequential_overlap`` frames. office.mp4 at half
    its frame rate split more with the next 8 frames (160 of 187 in its largest model, against 175 with these);
    along a walk the far ones seldom verify, and skipping them showed no time saved
    (docs/investigations/sfm.md#sequential-neighbours)."""
    loop_detection: bool = True
    """Sequential: find loops with visual words learned from the capture itself (office: without it the walk
    splits into 6 models at fast turns)."""
    loop_detection_period: int = 10
    """Sequential loop detection: query every N-th frame."""
    loop_detection_num_images: int = 30
    """Sequential loop detection: each queried frame is matched against its N most similar frames."""
    vocab_tree_descriptors: int = 100_000
    """The capture's visual words (loop detection, retrieval, the pairs between takes): trained on at most this many
    of its descriptors, so their training time stays fixed."""
    cross_take_matching: bool = True
    """Sequential, with two or more takes (videos; the photos of a folder): also match frames with the most similar
    frames of the other takes (the capture's visual words), so a second pass joins the first."""
    cross_take_period: int = 2
    """Cross-take matching: query every N-th frame of each take."""
    cross_take_num_images: int = 5
    """Cross-take matching: each queried frame is matched against its N most similar frames of each other take."""
    spatial_neighbors: int = 50
    """Spatial (GPS): neighbours per image."""
    guided_matching: Guided = "auto"
    """COLMAP's guided matching: each pair matched again along its verified geometry (more matches, slower);
    auto: on for a sequence of frames (a video, numbered photos), where a fast turn or blur leaves consecutive
    frames few matches; where photos have over 3,000 features, only for the pairs with under 300 verified matches.

    office.mp4 with a second cut out at a turn: one model of 361 of 361 frames with it, models of 205 (placed 32
    deg off) and 166 without; at half the frame rate 171 of 187 in one model against 83 (docs/sfm.md#same-model).
    Before 0.3 a boolean: true is on, false off."""
    guided_only_below_inliers: int = 300
    """Guided matching chosen by auto, on photos of many features (a median of at least
    ``guided_selective_above_features``): each pair is matched first without guidance and matched again along its
    verified geometry only where fewer than this many matches pass verification (a fast turn, blur, a far pair),
    its rows then those that guiding every pair writes; a pair with more keeps its unguided matches. At 4,500
    features a photo a guided match costs 4 times an unguided one and adds about a fifth to a pair's 1,400 matches
    (docs/investigations/sfm.md#guided-where-weak). 0: every pair guided."""
    guided_selective_above_features: int = 3000
    """The median of SIFT features a photo from which auto's guided matching is selective
    (``guided_only_below_inliers``). Under it (office.mp4's frames: 1,127) a guided match costs under twice an
    unguided one and most pairs are weak, so matching every pair twice would cost more: every pair is guided."""
    # --- mapping
    mapper: Mapper = "auto"
    """How matches become cameras: incremental (COLMAP's), global (COLMAP's global mapper, formerly GLOMAP), or auto:
    incremental, then global on the same matches when the incremental model leaves photos out, the global model kept
    where it agrees with the incremental parts and holds more photos than their largest, by at least 5% of the
    photos."""
    global_ba_above: int = 300
    """Pools of more photos than this get the incremental mapper's cheaper schedule of whole-model adjustments
    (global_ba_growth, global_ba_refinements), as do matches past global_ba_above_observations; the rest keep
    COLMAP's."""
    global_ba_above_observations: int = 200_000
    """Matches that promise more observations than this (keypoints with a verified match) get the cheaper schedule
    whatever the count of photos.

    A global adjustment costs about its observations, not its photos: a 75-photo drone flight promises 360,000 (its
    mapping 1.7 times cheaper with the cheaper schedule, poses within 0.09 deg), a feature-rich 300-photo orbit
    1.2 million (2.0 times cheaper, as close to its truth), a 371-frame walk 255,000; 200,000 is about 300 frames
    of a walk (docs/sfm.md#large-pools)."""
    global_ba_growth: float = 1.5
    """Past global_ba_above or global_ba_above_observations: a global bundle adjustment each time the model grows by
    this factor (COLMAP: 1.1)."""
    global_ba_refinements: int = 1
    """Past global_ba_above or global_ba_above_observations: each global bundle adjustment refined (adjust,
    retriangulate, filter) at most this many times (COLMAP: 5)."""
    repeat_final_refinement: bool = False
    """Where no photo more registers, the incremental mapper refines the whole model and tries once more; COLMAP's
    pipeline then refines it again at the end even where nothing registered in between (True: as COLMAP, the model
    of ``pycolmap.incremental_mapping``). False: that refinement is the last, as COLMAP's own rule for the end has
    it ("only if the last adjustment was not global"): office.mp4's mapping 68 -> 57 CPU s; every model of ten
    captures keeps its photos; of six with truth two come closer to it, three stay, the two takes move 0.15 deg
    further at the median (docs/investigations/sfm.md#final-refinement)."""
    direct_ba_max_fill: float = 270.0
    """Pools past 1,000 photos: a global bundle adjustment of more than 1,000 photos solves directly (sparse
    Cholesky) while the factor's fill stays under this many nonzeros per photo (a walk that covers new ground), else
    iteratively, Ceres' choice past 1,000 (a room seen round and round); 0: Ceres' choice always
    (docs/sfm.md#large-pools)."""
    min_registered_fraction: float = 0.95
    """'auto': the share of the kept photos the incremental model must hold."""
    min_global_gain: float = 0.05
    """'auto': the global model (the less accurate of the two on real walks) replaces the incremental ones only when
    it holds at least this share of the photos more than their largest (three takes, one foreign: 2 photos more for
    12 frames over 5 deg; docs/sfm.md)."""
    max_part_disagreement_deg: float = 3.0
    """'auto': the global model replaces the incremental parts only when it agrees with each within this many degrees
    (orientation difference, on 90% of the part's photos)."""
    min_num_matches: int = 15
    """Minimum verified matches for an image pair to count."""
    init_min_num_inliers: int = 200
    """Verified inliers of the mapper's initial pair (COLMAP: 100; it halves this, twice at most, when no pair
    qualifies). office: a 124-inlier planar initial pair got a wrong relative pose, a kink that bent the walk by 17
    deg."""
    register_min_inliers: int = 20
    """Fewest 2D-3D inliers for the incremental mapper to register a photo, and fewest points of the model a photo
    must see to be tried at all (COLMAP's ``abs_pose_min_num_inliers``: 30). At 30 a stretch of a video whose
    frames each see under 30 of the model's points is never tried, though its frames overlap: office.mp4 split
    at a fast turn, 12 frames left to a wrong part of their own; at 20 the walk is one model of 371 and the cut
    walk one of 361 (docs/investigations/sfm.md#registering-at-20)."""
    seed: int = 0
    """Random seed of COLMAP (verification RANSAC, mapper) and of the visual words' k-means: same photos
    and config, same matches and model."""
    video: VideoConfig = field(default_factory=VideoConfig)
    """Videos among the photos (or given instead of a folder): how their candidate frames are chosen."""
    # --- outputs
    dense: AutoOff = "auto"
    """'auto': dense point cloud when pycolmap has CUDA; 'off': none."""
    triangulate: AutoOff = "auto"
    """Known poses (--poses) that come without 3D points (a transforms.json, a cameras.json, a COLMAP model
    without points): auto triangulates points from the photos with the poses held fixed (SIFT features and
    matches as SfM makes them, at the working size of --max-size), so the run and the export's sparse/0
    carry the point cloud 3DGS starts from; off imports the poses alone, without points."""
    on_split: OnSplit = "largest"
    """When SfM leaves kept photos out of its largest model (the capture split): 'largest' curates the largest part
    with a loud warning; 'each' also curates every other part of >= 10 photos in RUN/parts/<k> (the budget shared by
    size; each part is its own scene, in its own frame); 'stop' stops."""
    normalize_percentile: float = 1.0
    """Scene box: points' [p, 100 - p] percentiles plus camera centres."""
    # --- execution (not in the stage key)
    num_threads: int = -1
    """Threads of ingest and SIFT extraction, processes of matching (-1: all cores; ingest uses max(1, this) or 2).
    Each matching process matches its piece of the pair list on one thread, so the matches are the same whatever
    the number (``curate.sfm.matching.match_list``); mapping runs on one thread, so that every run gives the same
    model (``MAPPING_THREADS``)."""
    progress: bool = True
    """tqdm bars on the terminal."""

    def __post_init__(self) -> None:
        if isinstance(self.guided_matching, bool):   # a run folder of curate 0.2 (a boolean then)
            self.guided_matching = "on" if self.guided_matching else "off"
        choices = {"camera_mode": CAMERA_MODES, "matcher": MATCHERS, "dense": TRIANGULATE, "on_split": ON_SPLIT,
                   "mapper": MAPPERS, "triangulate": TRIANGULATE, "guided_matching": GUIDED}
        for k, ok in choices.items():
            if getattr(self, k) not in ok:
                raise ValueError(f"sfm: {k.replace('_', ' ')} must be one of {ok}, got {getattr(self, k)!r}")
        if self.max_image_size < 64:
            raise ValueError(f"--max-size must be >= 64 (pixels), got {self.max_image_size}")
        if not (isinstance(self.sift_peak_threshold, (int, float)) and 0 < self.sift_peak_threshold < 1):
            raise ValueError(f"--sift-peak-threshold must be a number in (0, 1) (COLMAP's default 0.0067; lower "
                             f"finds more features), got {self.sift_peak_threshold!r}")
        if not isinstance(self.sift_upsample_below, int) or isinstance(self.sift_upsample_below, bool) \
                or self.sift_upsample_below < 0 or self.sift_min_features_undoubled < 0:
            raise ValueError(f"--sift-upsample-below must be a whole number of pixels >= 0, got "
                             f"{self.sift_upsample_below!r} (and SfmConfig.sift_min_features_undoubled >= 0)")
        if not self.max_part_disagreement_deg > 0:
            raise ValueError("SfmConfig.max_part_disagreement_deg must be > 0")
        if not (0 <= self.min_registered_fraction <= 1) or not (0 <= self.min_global_gain <= 1):
            raise ValueError("SfmConfig.min_registered_fraction and min_global_gain must be in [0, 1]")
        if not self.global_ba_growth > 1 or self.global_ba_refinements < 1 or self.global_ba_above < 0 \
                or self.global_ba_above_observations < 0:
            raise ValueError("SfmConfig.global_ba_growth must be > 1, global_ba_refinements >= 1, global_ba_above and "
                             "global_ba_above_observations >= 0")
        if self.register_min_inliers < 4:
            raise ValueError("SfmConfig.register_min_inliers must be >= 4 (a pose from 2D-3D matches needs more than "
                             f"three), got {self.register_min_inliers}")
        if not self.direct_ba_max_fill >= 0:
            raise ValueError("SfmConfig.direct_ba_max_fill must be >= 0")
        if self.guided_only_below_inliers < 0 or self.guided_selective_above_features < 0:
            raise ValueError("SfmConfig.guided_only_below_inliers and guided_selective_above_features must be >= 0")
        if self.retrieval_num_images < 1 or self.retrieval_rematch_num_images < 1:
            raise ValueError("SfmConfig.retrieval_num_images and retrieval_rematch_num_images must be >= 1")
        if self.cross_take_period < 1 or self.cross_take_num_images < 1:
            raise ValueError("SfmConfig.cross_take_period and cross_take_num_images must be >= 1")
        if self.vocab_tree_descriptors < 256 * 40:
            raise ValueError("SfmConfig.vocab_tree_descriptors must be >= 10240 (256 visual words)")
