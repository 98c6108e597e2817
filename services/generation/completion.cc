#include "services/generation/completion.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>

#include "absl/strings/str_cat.h"
#include "common/core/parallel.h"
#include "common/core/status.h"
#include "common/mesh/mesh_ply.h"
#include "common/mesh/surfel_mesh.h"
#include "common/scene/image_io.h"
#include "common/splat/gaussian_ply.h"
#include "services/generation/completion_manifest.h"
#include "services/generation/refinement_views.h"

namespace instascene::generation {
namespace {

// Observed surfels followed by completed ones, core attributes only, with the provenance channel.
GaussianCloud MergeWithProvenance(const GaussianCloud& observed, const GaussianCloud& added) {
  GaussianCloud out;
  out.num_scales = 2;
  out.sh_degree = observed.sh_degree;
  auto append = [&](const GaussianCloud& c) {
    out.positions.insert(out.positions.end(), c.positions.begin(), c.positions.end());
    out.log_scales.insert(out.log_scales.end(), c.log_scales.begin(), c.log_scales.end());
    out.rotations.insert(out.rotations.end(), c.rotations.begin(), c.rotations.end());
    out.opacity_logits.insert(out.opacity_logits.end(), c.opacity_logits.begin(),
                              c.opacity_logits.end());
    out.sh.insert(out.sh.end(), c.sh.begin(), c.sh.end());
  };
  append(observed);
  append(added);
  std::vector<float> provenance(observed.size(), 0.0f);
  provenance.resize(observed.size() + added.size(), 1.0f);
  out.SetExtra(kProvenanceChannel, ScalarType::kUint8, std::move(provenance));
  return out;
}

// The scene's camera extent as 2DGS scales its position learning rate (getNerfppNorm: 1.1 x the
// largest distance of a camera centre from their mean).
double CameraExtent(const std::vector<PinholeCamera>& cameras) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const PinholeCamera& c : cameras) mean += c.CenterInWorld();
  mean /= std::max<size_t>(1, cameras.size());
  double radius = 0;
  for (const PinholeCamera& c : cameras)
    radius = std::max(radius, (c.CenterInWorld() - mean).norm());
  return radius > 0 ? 1.1 * radius : 1.0;
}

// The real views' crops for refinement (view 0 is the best training view); views without an
// image, or where the object does not show, are counted in `skipped`.
absl::StatusOr<std::vector<RefinementView>> RealViews(const CompletedObject& o,
                                                      const std::vector<PinholeCamera>& cameras,
                                                      const GaussianCloud& surfels,
                                                      const std::vector<uint32_t>& instance,
                                                      const CompletionOptions& options,
                                                      int* skipped) {
  std::vector<RefinementView> views;
  if (!options.load_view) return views;
  for (int v : o.training_views) {
    absl::StatusOr<Image> image = options.load_view(v);
    if (absl::IsNotFound(image.status())) {  // a view without an image
      ++*skipped;
      continue;
    }
    RETURN_IF_ERROR(image.status());
    ASSIGN_OR_RETURN(std::optional<RefinementView> view,
                     RealRefinementView(cameras[v], *image, o.object, surfels, instance, o.frame,
                                        options.refine_view_max_side, options.num_threads));
    if (view.has_value()) {
      views.push_back(std::move(*view));
    } else {
      ++*skipped;
    }
  }
  return views;
}

nlohmann::json RefinementManifest(const RefinementReport& r, const RefinementOptions& ro,
                                  const CompletedObject& o, const CompletionOptions& options,
                                  int skipped) {
  return nlohmann::json{
      {"status", "done"},
      {"iterations", r.iterations},
      {"real_views", r.real_views},
      {"real_views_skipped", skipped},
      {"real_images", static_cast<bool>(options.load_view)},
      {"generated_views", r.generated_views},
      {"generated_from", o.prior.generated.empty() ? "the object's own renders before refinement"
                                                   : "the prior's images"},
      {"initial_loss", r.initial_loss},
      {"final_loss", r.final_loss},
      {"loss_curve", r.loss_curve},
      {"curve_every", ro.curve_every},
      {"spatial_scale", ro.spatial_scale},
      {"seconds", r.seconds},
      {"terms",
       "real: L1 over the crop, the object rendered in situ (the rest of the scene "
       "frozen); generated: 0.8 L1 + 0.2 D-SSIM + 0.1 BCE(alpha, mask)"},
      {"not_implemented", "normal consistency (needs the depth/normal backward)"}};
}

// Joint refinement of o->object (ALGORITHM.md 7.9): real-view crops first, then the ring's
// generated views. Returns the manifest's `refinement`.
absl::StatusOr<nlohmann::json> Refine(CompletedObject* o, const std::vector<PinholeCamera>& cameras,
                                      const GaussianCloud& surfels,
                                      const std::vector<uint32_t>& instance,
                                      const CompletionOptions& options,
                                      const CompletionProgress& progress) {
  if (options.refinement.iterations == 0) {
    return nlohmann::json{{"status", "not run"}, {"reason", "refinement iterations = 0"}};
  }
  int skipped = 0;
  ASSIGN_OR_RETURN(std::vector<RefinementView> views,
                   RealViews(*o, cameras, surfels, instance, options, &skipped));
  ASSIGN_OR_RETURN(std::vector<RefinementView> generated,
                   GeneratedRefinementViews(o->object, o->ring, o->frame, o->prior.generated,
                                            options.num_threads));
  for (RefinementView& v : generated) views.push_back(std::move(v));
  RefinementOptions ro = options.refinement;
  ro.seed = options.seed;
  ro.num_threads = options.num_threads;
  ro.cancel = options.cancel;
  ro.spatial_scale = CameraExtent(cameras);
  ASSIGN_OR_RETURN(RefinementReport r,
                   RefineGaussians(&o->object, views, ro, [&](int it, int total, double loss) {
                     if (progress) progress(absl::StrCat("refining: loss ", loss), it, total);
                   }));
  return RefinementManifest(r, ro, *o, options, skipped);
}

// The instance, its strays and support surfels moved to the occluders, and its frame (into
// `out`: id, frame, raw, stray_removed). FailedPrecondition for a degenerate instance.
absl::StatusOr<InstanceSplit> FrameInstance(const std::vector<PinholeCamera>& cameras,
                                            const GaussianCloud& surfels,
                                            const std::vector<uint32_t>& labels, uint32_t id,
                                            const CompletionOptions& options,
                                            CompletedObject* out) {
  ASSIGN_OR_RETURN(InstanceSplit split, SplitInstance(labels, id, options.min_gaussians));
  const StrayComponents strays = RemoveStrayGaussians(surfels, &split);
  out->id = id;
  out->frame = ComputeObjectFrame(surfels, split, cameras);
  if (ReturnTips(surfels, out->frame, strays, &split) > 0) {
    out->frame = ComputeObjectFrame(surfels, split, cameras);  // the top was short of the tip
  }
  if (RemoveSupportSurfels(surfels, out->frame, &split) > 0) {
    out->frame = ComputeObjectFrame(surfels, split, cameras);  // the bottom was the support's
  }
  out->stray_removed = split.outliers;
  out->raw = surfels.Subset(split.instance);
  out->raw.extras.clear();
  if (!(out->frame.radius > 0) || !(out->frame.spacing > 0)) {
    return absl::FailedPreconditionError(
        absl::StrCat("instance ", id, " is degenerate: its Gaussians span no volume"));
  }
  return split;
}

// The real views ranked for refinement and the ring's visibility (into `out`).
absl::Status ScoreViews(const std::vector<PinholeCamera>& cameras, const GaussianCloud& surfels,
                        const InstanceSplit& split, const CompletionOptions& options,
                        CompletedObject* out) {
  ASSIGN_OR_RETURN(std::unique_ptr<OcclusionScorer> scorer,
                   OcclusionScorer::Create(surfels, split, out->frame, options.visibility));
  out->training_views = scorer->RankViews(cameras, options.top_training_views);
  if (out->training_views.empty()) {
    return absl::FailedPreconditionError(
        absl::StrCat("instance ", out->id, " is seen by no real view (no unoccluded point)"));
  }
  out->ring = RingCameras(out->frame, options.ring);
  for (const PinholeCamera& c : out->ring) out->ring_visibility.push_back(scorer->Score(c));
  return absl::OkStatus();
}

// The free space the real views carved around the object (every scene surfel occludes).
absl::StatusOr<FreeSpaceGrid> CarveFreeSpace(const std::vector<PinholeCamera>& cameras,
                                             const GaussianCloud& surfels, const ObjectFrame& frame,
                                             const CompletionOptions& options) {
  std::vector<uint32_t> everything(surfels.size());
  for (uint32_t g = 0; g < everything.size(); ++g) everything[g] = g;
  ASSIGN_OR_RETURN(std::unique_ptr<RayCaster> scene_caster,
                   RayCaster::Create(SurfelDiscs(surfels, everything, SurfelDiscOptions{})));
  return FreeSpaceGrid::Carve(cameras, *scene_caster, frame, options.free_space);
}

// The ring's known views rendered as the prior's conditions; the unknown ones are its targets.
absl::Status AddRingViews(const CompletedObject& out, int num_threads, PriorInput* input) {
  for (size_t k = 0; k < out.ring.size(); ++k) {
    if (out.ring_visibility[k].known) {
      ASSIGN_OR_RETURN(ViewImages view,
                       RenderObjectView(out.raw, out.ring[k], out.frame, num_threads));
      input->conditions.push_back(std::move(view));
    } else {
      input->targets.push_back(out.ring[k]);
    }
  }
  return absl::OkStatus();
}

// The surfels the prior found to be a neighbour's (indices into the raw instance) become
// occluders, like the strays.
void DropForeignSurfels(InstanceSplit* split, CompletedObject* out) {
  if (out->prior.foreign.empty()) return;
  std::vector<uint8_t> drop(split->instance.size(), 0);
  for (uint32_t g : out->prior.foreign) {
    if (g < drop.size()) drop[g] = 1;
  }
  std::vector<uint32_t> kept, instance;
  for (uint32_t g = 0; g < drop.size(); ++g) {
    if (drop[g]) {
      split->occluders.push_back(split->instance[g]);
      continue;
    }
    kept.push_back(g);
    instance.push_back(split->instance[g]);
  }
  std::sort(split->occluders.begin(), split->occluders.end());
  split->outliers += split->instance.size() - instance.size();
  split->instance = std::move(instance);
  out->raw = out->raw.Subset(kept);
  out->stray_removed = split->outliers;
}

// About an accepted axis of revolution the completion went all round and the inside (a cup's
// cavity) is the axis's to shape; any other object's unknown inside is solid, a box's too
// (MeshingOptions::enclose_hull, PriorOutput::revolution_axis).
absl::Status MeshCompleted(const FreeSpaceGrid& free_space, const CompletionOptions& options,
                           CompletedObject* out) {
  out->hull_enclosed =
      options.meshing.closed && options.meshing.enclose_hull && !out->prior.revolution_axis;
  ASSIGN_OR_RETURN(
      out->mesh,
      MeshObject(out->object, out->frame, options.meshing, options.num_threads,
                 out->hull_enclosed ? [&](const Eigen::Vector3f& p) { return free_space.IsFree(p); }
                                    : std::function<bool(const Eigen::Vector3f&)>{},
                 options.meshing.sides_within_order_axis_copies && out->prior.order_axis));
  return absl::OkStatus();
}

absl::Status CheckArenaInputs(const GaussianCloud& surfels, const std::vector<uint32_t>& labels) {
  if (labels.size() != surfels.size()) {
    return absl::InvalidArgumentError(absl::StrCat("segmentation has ", labels.size(),
                                                   " labels for ", surfels.size(), " Gaussians"));
  }
  if (surfels.num_scales != 2) return absl::InvalidArgumentError("completion needs 2DGS surfels");
  return absl::OkStatus();
}

// What the prior is given (pointers into `out` and the arena's tests; the ring views are added
// by AddRingViews).
PriorInput PriorInputOf(const CompletedObject& out, const FreeSpaceGrid& free_space,
                        const std::optional<SeenThroughTest>& seen_through,
                        const std::vector<uint8_t>& neighbour_labelled,
                        const CompletionOptions& options) {
  PriorInput input;
  input.instance = &out.raw;
  input.frame = out.frame;
  input.free_space = &free_space;
  input.seen_through = seen_through ? &*seen_through : nullptr;
  input.neighbour_labelled = &neighbour_labelled;
  input.seed = options.seed;
  input.cancel = options.cancel;
  return input;
}

absl::StatusOr<CompletedObject> CompleteInArena(const std::vector<PinholeCamera>& cameras,
                                                const GaussianCloud& surfels,
                                                const std::vector<uint32_t>& labels, uint32_t id,
                                                const CompletionOptions& options,
                                                const CompletionProgress& progress) {
  auto report = [&](const std::string& phase, int step, int total) {
    if (progress) progress(phase, step, total);
  };
  RETURN_IF_ERROR(CheckArenaInputs(surfels, labels));
  ASSIGN_OR_RETURN(
      std::unique_ptr<CompletionPrior> prior,
      MakePrior(options.prior, options.denoiser, options.diffusion, &options.geometric));
  report("framing", 0, 7);
  CompletedObject out;
  ASSIGN_OR_RETURN(InstanceSplit split, FrameInstance(cameras, surfels, labels, id, options, &out));
  report("scoring views", 1, 7);
  RETURN_IF_ERROR(ScoreViews(cameras, surfels, split, options, &out));
  RETURN_IF_ERROR(CheckCancelled(options.cancel, "complete"));
  report("carving free space", 2, 7);
  ASSIGN_OR_RETURN(const FreeSpaceGrid free_space,
                   CarveFreeSpace(cameras, surfels, out.frame, options));
  std::optional<SeenThroughTest> seen_through;
  if (prior->UsesSeenThrough()) {
    ASSIGN_OR_RETURN(seen_through, SeenThroughTest::Create(cameras, surfels, out.frame.radius,
                                                           options.seen_through));
  }
  RETURN_IF_ERROR(CheckCancelled(options.cancel, "complete"));
  report("rendering conditions", 3, 7);
  const std::vector<uint8_t> neighbour_labelled =
      NeighbourLabelled(surfels, labels, split, out.frame);
  PriorInput input = PriorInputOf(out, free_space, seen_through, neighbour_labelled, options);
  RETURN_IF_ERROR(AddRingViews(out, options.num_threads, &input));
  report("completing", 4, 7);
  ASSIGN_OR_RETURN(out.prior, prior->Complete(input));
  DropForeignSurfels(&split, &out);
  out.object = MergeWithProvenance(out.raw, out.prior.added);
  RETURN_IF_ERROR(CheckCancelled(options.cancel, "complete"));
  report("refining", 5, 7);
  ASSIGN_OR_RETURN(out.refinement,
                   Refine(&out, cameras, surfels, split.instance, options, progress));
  RETURN_IF_ERROR(CheckCancelled(options.cancel, "complete"));
  report("meshing", 6, 7);
  RETURN_IF_ERROR(MeshCompleted(free_space, options, &out));
  out.manifest = CompletionManifest(out, options);
  report("done", 7, 7);
  return out;
}

}  // namespace

absl::StatusOr<CompletedObject> CompleteObject(const std::vector<PinholeCamera>& cameras,
                                               const GaussianCloud& surfels,
                                               const std::vector<uint32_t>& labels, uint32_t id,
                                               const CompletionOptions& options,
                                               const CompletionProgress& progress) {
  // Every TBB loop inside runs in an arena of num_threads (the results never depend on it).
  return RunWithThreads(options.num_threads, [&] {
    return CompleteInArena(cameras, surfels, labels, id, options, progress);
  });
}

absl::Status WriteCompletedObject(const std::string& directory, const CompletedObject& object,
                                  int num_threads) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(fs::path(directory) / "views", ec);
  if (ec) return absl::UnavailableError(absl::StrCat(directory, ": cannot create: ", ec.message()));
  RETURN_IF_ERROR(WriteGaussianPly((fs::path(directory) / "object.ply").string(), object.object));
  RETURN_IF_ERROR(WriteMeshPly((fs::path(directory) / "mesh.ply").string(), object.mesh));
  // The least-known ring view: where the prior had to work hardest.
  size_t worst = 0;
  for (size_t k = 1; k < object.ring_visibility.size(); ++k) {
    if (object.ring_visibility[k].score < object.ring_visibility[worst].score) worst = k;
  }
  if (!object.ring.empty()) {
    ASSIGN_OR_RETURN(ViewImages raw,
                     RenderObjectView(object.raw, object.ring[worst], object.frame, num_threads));
    ASSIGN_OR_RETURN(ViewImages done, RenderObjectView(object.object, object.ring[worst],
                                                       object.frame, num_threads));
    const int w = object.ring[worst].width, h = object.ring[worst].height;
    Image side_by_side{2 * w, h, 3, std::vector<float>(static_cast<size_t>(6) * w * h)};
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        for (int c = 0; c < 3; ++c) {
          side_by_side.pixels[(static_cast<size_t>(y) * 2 * w + x) * 3 + c] =
              raw.rgb[(static_cast<size_t>(y) * w + x) * 3 + c];
          side_by_side.pixels[(static_cast<size_t>(y) * 2 * w + w + x) * 3 + c] =
              done.rgb[(static_cast<size_t>(y) * w + x) * 3 + c];
        }
      }
    }
    RETURN_IF_ERROR(
        WriteImage((fs::path(directory) / "views" / "compare_unknown.png").string(), side_by_side));
  }
  nlohmann::json manifest = object.manifest;
  manifest["files"] = {{"object", "object.ply"},
                       {"mesh", "mesh.ply"},
                       {"compare_unknown", "views/compare_unknown.png"}};
  manifest["compare_view"] = worst;
  return WriteFileAtomically((fs::path(directory) / "manifest.json").string(), manifest.dump(1));
}

}  // namespace instascene::generation
