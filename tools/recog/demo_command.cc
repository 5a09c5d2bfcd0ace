// recog demo: the offline demonstration run by the README's first command. It converts the
// bundled corridor frames into bags of words with the bundled place vocabulary and prints their
// L1 similarity matrix: revisits of the same place (41 -> 1, 60 -> 20) stand out.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/bow/scoring.h"
#include "core/features/feature_extractor.h"
#include "core/vocabulary/vocabulary_io.h"
#include "tools/common/cli_support.h"
#include "tools/recog/commands.h"

namespace recog::cli {
namespace {

int RunDemo(const std::string& images_dir, const std::string& vocabulary_path) {
  auto fail = [](const Status& s) {
    std::fprintf(stderr, "recog demo: %s\n", s.ToString().c_str());
    return 1;
  };
  auto vocabulary = LoadAnyVocabulary(vocabulary_path);
  if (!vocabulary.ok()) return fail(vocabulary.status());
  auto files = ListImages(images_dir);
  if (!files.ok()) return fail(files.status());
  auto extractor = CreateFeatureExtractor(PlaceFeatureOptions());
  if (!extractor.ok()) return fail(extractor.status());

  std::printf("vocabulary %s: %zu words (k=%u, L=%u)\n", vocabulary_path.c_str(),
              vocabulary->num_words(), vocabulary->info().branching, vocabulary->info().depth);
  std::vector<BowVector> bows(files->size());
  std::vector<std::string> names;
  for (size_t i = 0; i < files->size(); ++i) {
    auto image = ReadGrayImage((*files)[i]);
    if (!image.ok()) return fail(image.status());
    FeatureSet features;
    if (Status s = (*extractor)->Extract(*image, &features); !s.ok()) return fail(s);
    if (Status s = vocabulary->Transform(features.descriptors, &bows[i]); !s.ok()) return fail(s);
    names.push_back(std::filesystem::path((*files)[i]).filename().string());
    std::printf("  %-8s %4zu ORB features -> %4zu words\n", names.back().c_str(), features.size(),
                bows[i].size());
  }
  std::printf("\nL1 similarity (1 = identical, 0 = nothing in common):\n%8s", "");
  for (const std::string& n : names) std::printf(" %8s", n.c_str());
  std::printf("\n");
  for (size_t i = 0; i < bows.size(); ++i) {
    std::printf("%8s", names[i].c_str());
    for (size_t j = 0; j < bows.size(); ++j) {
      std::printf(" %8.3f", Score(ScoringType::kL1, bows[i], bows[j]));
    }
    std::printf("\n");
  }
  std::printf("\nFor each image, the most similar other image:\n");
  for (size_t i = 0; i < bows.size(); ++i) {
    size_t best = i;
    double best_score = -1;
    for (size_t j = 0; j < bows.size(); ++j) {
      const double s = j == i ? -1 : Score(ScoringType::kL1, bows[i], bows[j]);
      if (s > best_score) {
        best_score = s;
        best = j;
      }
    }
    std::printf("  %-8s -> %-8s (%.3f)\n", names[i].c_str(), names[best].c_str(), best_score);
  }
  return 0;
}

}  // namespace

void AddDemoCommand(CLI::App& app, int* exit_code) {
  auto images = std::make_shared<std::string>(DemoImageDir());
  auto vocabulary = std::make_shared<std::string>(DefaultPlaceVocabularyPath());
  CLI::App* demo = app.add_subcommand(
      "demo", "Offline demo: bags of words and similarities of the bundled corridor frames");
  demo->add_option("--images", *images, "Folder of images")->capture_default_str();
  demo->add_option("--vocab", *vocabulary, "Vocabulary file")->capture_default_str();
  demo->callback([=] { *exit_code = RunDemo(*images, *vocabulary); });
}

}  // namespace recog::cli
