// stream_folder SERVER FOLDER [MAP]: streams the images of FOLDER (JPEG or PNG, in natural order of
// their numbered names) into place map MAP (default "consumer", created if missing) of the recogd
// at SERVER through recog's C++ client, and prints every loop closure it answers.
#include <algorithm>
#include <deque>
#include <filesystem>
#include <future>
#include <iostream>
#include <string>
#include <vector>

#include "client/cpp/frame_stream.h"
#include "client/cpp/frames.h"
#include "client/cpp/recognition_client.h"

namespace fs = std::filesystem;
using namespace recog::client;

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: stream_folder SERVER FOLDER [MAP]\n";
    return 2;
  }
  std::vector<fs::path> images;
  for (const fs::directory_entry& entry : fs::directory_iterator(argv[2])) {
    const std::string ext = entry.path().extension().string();
    if (ext == ".jpg" || ext == ".jpeg" || ext == ".png") images.push_back(entry.path());
  }
  std::sort(images.begin(), images.end(), [](const fs::path& a, const fs::path& b) {
    const std::string x = a.filename().string(), y = b.filename().string();
    return x.size() != y.size() ? x.size() < y.size() : x < y;  // 2.jpg before 10.jpg
  });

  ClientOptions options;
  options.target = argv[1];
  Result<std::unique_ptr<RecognitionClient>> client = RecognitionClient::Connect(options);
  if (!client.ok()) {
    std::cerr << "stream_folder: " << client.status().error_message() << "\n";
    return 1;
  }
  pb::StreamConfig config;
  config.set_map(argc > 3 ? argv[3] : "consumer");
  config.set_create_if_missing(true);
  Result<std::unique_ptr<FrameStream>> stream = FrameStream::Open(**client, config);
  if (!stream.ok()) {
    std::cerr << "stream_folder: " << stream.status().error_message() << "\n";
    return 1;
  }

  size_t answered = 0, loops = 0;
  std::deque<std::future<FrameStream::Answer>> pending;
  const auto take_oldest = [&] {  // answers come in the order the frames were sent
    FrameStream::Answer answer = pending.front().get();
    pending.pop_front();
    if (!answer.ok()) return;  // the stream failed: Close() says why
    ++answered;
    if (answer->has_error()) {
      std::cerr << answer->client_frame_id() << ": " << answer->error().message() << "\n";
    } else if (answer->result().status() == pb::LOOP_STATUS_LOOP_DETECTED) {
      ++loops;
      std::cout << "loop: " << answer->client_frame_id() << " -> "
                << answer->result().match_client_frame_id() << " (" << answer->result().inliers()
                << " inliers)\n";
    }
  };
  for (const fs::path& image : images) {
    Result<pb::Frame> frame = FrameFromEncodedFile(image.string());
    if (!frame.ok()) {
      std::cerr << image << ": " << frame.status().error_message() << "\n";
      return 1;
    }
    frame->set_client_frame_id(image.filename().string());
    pending.push_back((*stream)->Send(std::move(*frame)));
    if (pending.size() >= 8) take_oldest();  // a few frames in flight, well below the limit
  }
  while (!pending.empty()) take_oldest();
  const grpc::Status end = (*stream)->Close();
  std::cout << "streamed " << images.size() << " frames, " << answered << " answered, " << loops
            << " loops\n";
  if (!end.ok()) std::cerr << "stream_folder: " << end.error_message() << "\n";
  return end.ok() && answered == images.size() ? 0 : 1;
}
