// recog vocab train | info | convert
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/features/feature_extractor.h"
#include "core/features/training_images.h"
#include "core/vocabulary/dbow2_format.h"
#include "core/vocabulary/vocabulary_io.h"
#include "core/vocabulary/vocabulary_trainer.h"
#include "tools/common/cli_support.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

using Clock = std::chrono::steady_clock;
double SecondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

struct TrainArgs {
  std::string images;
  std::string output;
  std::string features_type = "orb";
  uint32_t k = 10;
  uint32_t levels = 5;
  uint32_t trees = 1;
  int features = 1000;
  uint32_t threads = 0;
  uint64_t seed = 42;
  uint32_t max_iterations = 10;
  std::string weighting = "tf-idf";
  bool quiet = false;
};

int RunTrain(const TrainArgs& args) {
  const auto start = Clock::now();
  auto files = ListImages(args.images);
  if (!files.ok()) return Fail("vocab train", files.status());
  FeatureOptions features;
  auto type = ParseFeatureType(args.features_type);
  if (!type.ok()) return Fail("vocab train", type.status());
  features.type = *type;
  features.orb.max_features = features.brief.max_features = features.sift.max_features =
      args.features;
  TrainingOptions options;
  options.branching = args.k;
  options.depth = args.levels;
  options.trees = args.trees;
  options.seed = args.seed;
  options.threads =
      args.threads == 0 ? std::max(1u, std::thread::hardware_concurrency()) : args.threads;
  options.max_iterations = args.max_iterations;
  auto weighting = ParseWeighting(args.weighting);
  if (!weighting.ok()) return Fail("vocab train", weighting.status());
  options.weighting = *weighting;
  if (Status s = options.Validate(); !s.ok()) return Fail("vocab train", s);
  if (Status s = features.Validate(); !s.ok()) return Fail("vocab train", s);

  ProgressBar progress(!args.quiet);
  const TrainingProgress report_progress = [&](std::string_view stage, uint64_t done,
                                               uint64_t total) {
    progress.Update(stage, done, total);
  };
  TrainingImagesReport report;
  auto set = ExtractTrainingSet(*files, features, options.threads, report_progress, &report);
  progress.Finish();
  if (!set.ok()) return Fail("vocab train", set.status());
  const double extraction_s = SecondsSince(start);
  const size_t images = set->num_images();
  const size_t descriptors = set->num_descriptors();
  if (!args.quiet) {
    std::fprintf(stderr, "%zu images (%zu unreadable skipped), %zu descriptors in %.1f s\n", images,
                 report.images_unreadable, descriptors, extraction_s);
  }
  options.progress = report_progress;
  const auto train_start = Clock::now();
  auto vocabulary = TrainVocabulary(std::move(set).value(), options);
  progress.Finish();
  if (!vocabulary.ok()) return Fail("vocab train", vocabulary.status());
  const double training_s = SecondsSince(train_start);
  if (Status s = SaveVocabulary(*vocabulary, args.output); !s.ok()) return Fail("vocab train", s);
  std::printf(
      "trained %s: %zu words, %zu nodes, k=%u L=%u trees=%u, %zu descriptors from %zu images\n"
      "time: features %.1f s, clustering+weighting %.1f s, total %.1f s; peak memory %.0f MiB; "
      "threads %u, seed %llu\n",
      args.output.c_str(), vocabulary->num_words(), vocabulary->num_nodes(), args.k, args.levels,
      args.trees, descriptors, images, extraction_s, training_s, SecondsSince(start), PeakRssMiB(),
      options.threads, static_cast<unsigned long long>(args.seed));
  return 0;
}

int RunInfo(const std::string& path, bool json) {
  const auto start = Clock::now();
  auto vocabulary = LoadAnyVocabulary(path);
  if (!vocabulary.ok()) return Fail("vocab info", vocabulary.status());
  const double load_ms = 1000 * SecondsSince(start);
  const VocabularyInfo& info = vocabulary->info();
  const auto format = DetectVocabularyFormat(path);
  const char* format_name = !format.ok()                                  ? "unknown"
                            : *format == VocabularyFileFormat::kRecog     ? "recog"
                            : *format == VocabularyFileFormat::kDbow2Text ? "dbow2-text"
                                                                          : "dbow2-yaml";
  if (json) {
    nlohmann::json j = {
        {"file", path},
        {"format", format_name},
        {"k", info.branching},
        {"levels", info.depth},
        {"trees", info.num_trees},
        {"words", vocabulary->num_words()},
        {"nodes", vocabulary->num_nodes()},
        {"descriptor", info.descriptor.ToString()},
        {"weighting", std::string(WeightingName(info.weighting))},
        {"scoring", std::string(ScoringName(info.scoring))},
        {"checksum", HexChecksum(vocabulary->checksum())},
        {"memory_bytes", vocabulary->MemoryBytes()},
        {"load_ms", load_ms},
    };
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf(
        "file:       %s (%s)\nk:          %u\nlevels:     %u\ntrees:      %u\nwords:      %zu\n"
        "nodes:      %zu\ndescriptor: %s\nweighting:  %s\nscoring:    %s\nchecksum:   %s\n"
        "memory:     %.1f MiB\nloaded in:  %.1f ms\n",
        path.c_str(), format_name, info.branching, info.depth, info.num_trees,
        vocabulary->num_words(), vocabulary->num_nodes(), info.descriptor.ToString().c_str(),
        std::string(WeightingName(info.weighting)).c_str(),
        std::string(ScoringName(info.scoring)).c_str(), HexChecksum(vocabulary->checksum()).c_str(),
        vocabulary->MemoryBytes() / 1048576.0, load_ms);
  }
  return 0;
}

int RunConvert(const std::string& in, const std::string& out, const std::string& to) {
  auto vocabulary = LoadAnyVocabulary(in);
  if (!vocabulary.ok()) return Fail("vocab convert", vocabulary.status());
  std::string target = to;
  if (target.empty())
    target = std::filesystem::path(out).extension() == ".txt" ? "dbow2-text" : "recog";
  Status s;
  if (target == "recog") {
    s = SaveVocabulary(*vocabulary, out);
  } else if (target == "dbow2-text") {
    s = ExportDbow2Text(*vocabulary, out);
  } else {
    s = Status::InvalidArgument("unknown output format '" + target + "' (recog or dbow2-text)");
  }
  if (!s.ok()) return Fail("vocab convert", s);
  std::printf("wrote %s (%s, %zu words)\n", out.c_str(), target.c_str(), vocabulary->num_words());
  return 0;
}

}  // namespace

void AddVocabCommands(CLI::App& app, int* exit_code) {
  CLI::App* vocab = app.add_subcommand("vocab", "Train, inspect and convert vocabularies");
  vocab->require_subcommand(1);

  auto train_args = std::make_shared<TrainArgs>();
  CLI::App* train = vocab->add_subcommand(
      "train", "Train a vocabulary from the features of every image under a folder");
  train->add_option("--images", train_args->images, "Folder of training images (recursive)")
      ->required();
  train->add_option("-o,--output", train_args->output, "Output vocabulary file (project format)")
      ->required();
  train->add_option("--k", train_args->k, "Branching factor")->capture_default_str();
  train->add_option("--levels", train_args->levels, "Depth L of each tree")->capture_default_str();
  train->add_option("--trees", train_args->trees, "Number of trees (12 for objects)")
      ->capture_default_str();
  train->add_option("--features", train_args->features, "Features per image")
      ->capture_default_str();
  train->add_option("--feature-type", train_args->features_type, "orb, brief or sift")
      ->capture_default_str();
  train->add_option("--weighting", train_args->weighting, "tf-idf, tf, idf or binary")
      ->capture_default_str();
  train->add_option("--threads", train_args->threads, "Threads (0 = all cores)")
      ->capture_default_str();
  train->add_option("--seed", train_args->seed, "Random seed")->capture_default_str();
  train
      ->add_option("--max-iterations", train_args->max_iterations,
                   "Lloyd iterations per split at most")
      ->capture_default_str();
  train->add_flag("-q,--quiet", train_args->quiet, "No progress output");
  train->callback([train_args, exit_code] { *exit_code = RunTrain(*train_args); });

  auto info_path = std::make_shared<std::string>();
  auto info_json = std::make_shared<bool>(false);
  CLI::App* info = vocab->add_subcommand("info", "Describe a vocabulary file (any format)");
  info->add_option("file", *info_path, "Vocabulary file")->required();
  info->add_flag("--json", *info_json, "Print JSON");
  info->callback([=] { *exit_code = RunInfo(*info_path, *info_json); });

  auto in = std::make_shared<std::string>();
  auto out = std::make_shared<std::string>();
  auto to = std::make_shared<std::string>();
  CLI::App* convert =
      vocab->add_subcommand("convert", "Convert between DBoW2 text/YAML and the project format");
  convert->add_option("input", *in, "Input vocabulary (project, DBoW2 .txt, .yml or .yml.gz)")
      ->required();
  convert->add_option("output", *out, "Output file")->required();
  convert->add_option("--to", *to,
                      "recog or dbow2-text (default: dbow2-text for .txt, recog otherwise)");
  convert->callback([=] { *exit_code = RunConvert(*in, *out, *to); });
}

}  // namespace recog::cli
