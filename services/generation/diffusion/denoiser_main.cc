// instascene-denoiser: serves an ONNX denoiser (onnx_denoiser.h) behind the Denoiser gRPC service
// (proto/instascene/v1/denoiser.proto), so that generation workers share one model process
// (`--denoiser grpc://HOST:PORT`). A site serving a real GPU model (MVD-Fusion) implements the same
// service in its own stack; docs/GENERATION.md "Serving a model". Plaintext gRPC: bind it to an
// internal address.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>

#include "common/core/file_io.h"
#include "common/rpc/server.h"
#include "services/generation/diffusion/grpc_denoiser.h"
#include "services/generation/diffusion/onnx_denoiser.h"

int main(int argc, char** argv) {
  using namespace instascene;
  using namespace instascene::generation::diffusion;
  CLI::App app{"instascene-denoiser: an ONNX noise predictor behind the Denoiser gRPC service"};
  std::string onnx, ready_file;
  rpc::ServerOptions server_options;
  app.add_option("--onnx", onnx,
                 "The model's JSON (file, I/O names, latent shape; docs/GENERATION.md)")
      ->required();
  app.add_option("--listen", server_options.listen, "host:port to serve on (port 0 = any free)")
      ->capture_default_str();
  app.add_option("--ready-file", ready_file,
                 "Write the bound address here once serving (removed at exit)");
  CLI11_PARSE(app, argc, argv);
  rpc::BlockShutdownSignals();
  auto fail = [](const absl::Status& s) {
    std::fprintf(stderr, "instascene-denoiser: error: %s\n", s.ToString().c_str());
    return 1;
  };
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  auto config = ReadOnnxDenoiserConfig(onnx);
  if (!config.ok()) return fail(config.status());
  auto model = OnnxDenoiser::Load(*config, schedule);
  if (!model.ok()) return fail(model.status());
  DenoiserService service(model->get(), (*model)->config().name, (*model)->config().latent_shape,
                          schedule.size());
  auto server = rpc::Server::Start(server_options, {&service}, {"instascene.v1.Denoiser"});
  if (!server.ok()) return fail(server.status());
  std::printf("instascene-denoiser: %s at %s\n", (*model)->config().name.c_str(),
              (*server)->address().c_str());
  std::fflush(stdout);
  if (!ready_file.empty()) {
    if (absl::Status s = WriteFileAtomically(ready_file, (*server)->address() + "\n"); !s.ok())
      return fail(s);
  }
  rpc::WaitForShutdownSignal();
  (*server)->Drain(std::chrono::seconds(5));
  if (!ready_file.empty()) {
    std::error_code ec;
    std::filesystem::remove(ready_file, ec);
  }
  return 0;
}
