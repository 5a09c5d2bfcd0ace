// recog bow IMAGE: the bag of words of one image.
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "core/common/elapsed.h"
#include "core/features/feature_extractor.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tools/common/cli_support.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

struct BowArgs {
  std::string image;
  std::string vocabulary;
  int features = 1000;
  int levels_up = 2;
  bool json = false;
};

int RunBow(const BowArgs& args) {
  auto fail = [](const Status& s) {
    std::fprintf(stderr, "recog bow: %s\n", s.ToString().c_str());
    return 1;
  };
  const std::string vocabulary_path =
      args.vocabulary.empty() ? DefaultPlaceVocabularyPath() : args.vocabulary;
  auto vocabulary = LoadAnyVocabulary(vocabulary_path);
  if (!vocabulary.ok()) return fail(vocabulary.status());
  auto image = ReadGrayImage(args.image);
  if (!image.ok()) return fail(image.status());

  FeatureOptions options;
  options.type = vocabulary->info().descriptor.type == DescriptorType::kFloat ? FeatureType::kSift
                                                                              : FeatureType::kOrb;
  options.orb.max_features = options.sift.max_features = args.features;
  auto extractor = CreateFeatureExtractor(options);
  if (!extractor.ok()) return fail(extractor.status());
  FeatureSet features;
  if (Status s = (*extractor)->Extract(*image, &features); !s.ok()) return fail(s);
  BowVector bow;
  FeatureVector direct;
  const auto start = std::chrono::steady_clock::now();
  if (Status s = vocabulary->Transform(features.descriptors, &bow, &direct, args.levels_up);
      !s.ok()) {
    return fail(s);
  }
  const double transform_ms = MillisecondsSince(start);

  if (args.json) {
    nlohmann::json words = nlohmann::json::array();
    for (const BowEntry& e : bow.entries()) words.push_back({{"word", e.word}, {"value", e.value}});
    nlohmann::json j = {{"image", args.image},
                        {"vocabulary", vocabulary_path},
                        {"vocabulary_checksum", HexChecksum(vocabulary->checksum())},
                        {"features", features.size()},
                        {"words", bow.size()},
                        {"direct_index_levels_up", args.levels_up},
                        {"direct_index_nodes", direct.size()},
                        {"transform_ms", transform_ms},
                        {"bow", words}};
    std::printf("%s\n", j.dump().c_str());
  } else {
    std::printf(
        "image %s: %zu features, %zu distinct words, %zu direct-index nodes at %d "
        "levels up (%.3f ms)\n",
        args.image.c_str(), features.size(), bow.size(), direct.size(), args.levels_up,
        transform_ms);
    for (const BowEntry& e : bow.entries()) std::printf("%u:%.6g\n", e.word, e.value);
  }
  return 0;
}

}  // namespace

void AddBowCommand(CLI::App& app, int* exit_code) {
  auto args = std::make_shared<BowArgs>();
  CLI::App* bow = app.add_subcommand("bow", "Print the bag-of-words vector of an image");
  bow->add_option("image", args->image, "Image file")->required();
  bow->add_option("--vocab", args->vocabulary,
                  "Vocabulary file, any format (default: the bundled place vocabulary)");
  bow->add_option("--features", args->features, "ORB features to extract")->capture_default_str();
  bow->add_option("--levels-up", args->levels_up, "Direct-index level above the words")
      ->capture_default_str();
  bow->add_flag("--json", args->json, "Print JSON");
  bow->callback([args, exit_code] { *exit_code = RunBow(*args); });
}

}  // namespace recog::cli
