// `instascene convert`: a splat file from another tool (Inria/2DGS or SuperSplat compressed PLY,
// .splat, .spz) to the internal PLY (or to .splat), as import and uploads read it.
#include <cstdio>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "clients/cli/cli.h"
#include "common/core/file_io.h"
#include "common/core/status.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/splat_formats.h"

namespace instascene::cli {

void AddConvertCommand(CLI::App& app, Action* action) {
  struct Args {
    std::string in, out;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "convert", "Convert a splat file (.ply, compressed .ply, .splat, .spz) to the internal PLY");
  cmd->add_option("--in", args->in, "The splat file to read (format detected from its content)")
      ->required();
  cmd->add_option("--out", args->out, "Where to write: NAME.ply (internal PLY) or NAME.splat")
      ->required();
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      ASSIGN_OR_RETURN(std::string data, ReadFileBounded(args->in, size_t{8} << 30));
      ASSIGN_OR_RETURN(SplatFormat format, DetectSplatFormat(data.substr(0, 1 << 20), args->in));
      ASSIGN_OR_RETURN(GaussianCloud cloud, ParseSplatFile(data, args->in));
      if (absl::EndsWith(args->out, ".splat")) {
        RETURN_IF_ERROR(WriteFileAtomically(args->out, EncodeSplat(cloud)));
      } else if (absl::EndsWith(args->out, ".ply")) {
        RETURN_IF_ERROR(WriteGaussianPly(args->out, cloud));
      } else {
        return absl::InvalidArgumentError(
            absl::StrCat("--out ", args->out, ": write .ply (internal PLY) or .splat"));
      }
      std::printf("%s (%s): %zu Gaussians, %d scales, SH degree %d -> %s\n", args->in.c_str(),
                  std::string(SplatFormatName(format)).c_str(), cloud.size(), cloud.num_scales,
                  cloud.sh_degree, args->out.c_str());
      return absl::OkStatus();
    };
  });
}

}  // namespace instascene::cli
