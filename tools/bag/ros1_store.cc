// The BagStore of a ROS 1 bag (rosbag 2.0), read with Debian's librosbag_storage: no ROS master,
// no ROS environment. The library reads the index, the chunks (bz2, lz4) and the messages' bytes;
// this file checks what its errors do not say (a bag cut short, or left unindexed by a recording
// that was not closed) and turns its exceptions into Status.
#include <algorithm>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <utility>

#include <ros/serialization.h>
#include <rosbag/bag.h>
#include <rosbag/exceptions.h>
#include <rosbag/query.h>
#include <rosbag/view.h>

#include "tools/bag/bag_store.h"
#include "tools/bag/byte_reader.h"

namespace recog::bag {
namespace {

namespace fs = std::filesystem;

std::string Quoted(const std::string& text) { return "'" + text + "'"; }

int64_t Nanoseconds(const ros::Time& t) { return int64_t(t.sec) * 1000000000 + int64_t(t.nsec); }

// The MD5 sums of ROS 1's sensor_msgs camera messages (those of their generated headers): a topic
// of one of these types with another sum has another definition, which the decoders would misread.
const std::map<std::string, std::string>& KnownDefinitions() {
  static const std::map<std::string, std::string> known = {
      {"sensor_msgs/Image", "060021388200f6f0f447d0fcd9c64743"},
      {"sensor_msgs/CompressedImage", "8f7a12909da2c9d3332d540a0977563f"},
      {"sensor_msgs/CameraInfo", "c9a58c1b0b154e0e6da7578cb991d214"}};
  return known;
}

// A record's header fields ("name=value"), as the bag format stores them.
std::map<std::string, std::string, std::less<>> HeaderFields(std::span<const uint8_t> header) {
  std::map<std::string, std::string, std::less<>> fields;
  ByteReader reader(header);
  while (reader.remaining() > 0) {
    const std::string_view field = reader.PrefixedText32();
    if (reader.failed()) break;
    const size_t equals = field.find('=');
    if (equals == std::string_view::npos) continue;
    fields.emplace(field.substr(0, equals), field.substr(equals + 1));
  }
  return fields;
}

// What the file says of itself before librosbag opens it: its index is there (the library's own
// errors do not say that a bag is truncated, or unindexed because its recording was not closed),
// and how its chunks are compressed (which the library does not tell).
struct Ros1FileFacts {
  std::set<std::string> compressions;  // of the chunks: "none", "bz2", "lz4"
};

StatusOr<Ros1FileFacts> CheckRos1File(const std::string& path) {
  std::error_code ec;
  const uintmax_t file_size = fs::file_size(path, ec);
  std::ifstream in(path, std::ios::binary);
  if (ec || !in) return Status::NotFound("bag " + Quoted(path) + " cannot be read");
  const auto truncated = [&](const std::string& where) {
    return Status::DataLoss("bag " + Quoted(path) + " is truncated: it ends (at byte " +
                            std::to_string(file_size) + ") inside " + where);
  };
  std::string magic(13, '\0');
  in.read(magic.data(), std::streamsize(magic.size()));
  Ros1FileFacts facts;
  if (magic.rfind("#ROSBAG V1.2", 0) == 0) return facts;  // the old format: no bag header
  if (magic != "#ROSBAG V2.0\n") {
    return Status::InvalidArgument(Quoted(path) +
                                   " is not a ROS 1 bag: it does not start with "
                                   "#ROSBAG V2.0");
  }
  // Records up to the index: header length, header fields, data length, data.
  std::optional<uint64_t> index_pos;
  uint64_t at = 13;
  while (!index_pos.has_value() || at < *index_pos) {
    uint8_t lengths[4];
    in.seekg(std::streamoff(at));
    if (!in.read(reinterpret_cast<char*>(lengths), 4)) {
      if (!index_pos.has_value()) return truncated("its header");
      return truncated("a chunk");
    }
    const uint32_t header_size = ByteReader(lengths).U32();
    if (header_size > (1u << 20) || at + 4 + header_size + 4 > file_size) {
      return index_pos.has_value() ? truncated("the record at byte " + std::to_string(at))
                                   : truncated("its header");
    }
    std::vector<uint8_t> header(header_size + 4);
    in.read(reinterpret_cast<char*>(header.data()), std::streamsize(header.size()));
    const auto fields = HeaderFields(std::span(header).first(header_size));
    const uint32_t data_size = ByteReader(std::span(header).last(4)).U32();
    const auto op = fields.find("op");
    const uint8_t opcode =
        op == fields.end() || op->second.size() != 1 ? 0 : uint8_t(op->second[0]);
    if (opcode == 0x03) {  // the bag header
      const auto index = fields.find("index_pos");
      if (index == fields.end() || index->second.size() != 8) {
        return Status::DataLoss("bag " + Quoted(path) + " is damaged: its header has no index_pos");
      }
      index_pos =
          ByteReader(std::span(reinterpret_cast<const uint8_t*>(index->second.data()), 8)).U64();
      if (*index_pos == 0) {
        return Status::DataLoss("bag " + Quoted(path) +
                                " is unindexed: its recording was not closed (or is still going "
                                "on); run `rosbag reindex " +
                                path + "` to rebuild its index");
      }
      if (*index_pos >= file_size) {
        return Status::DataLoss("bag " + Quoted(path) + " is truncated: it ends at byte " +
                                std::to_string(file_size) + ", before its index (byte " +
                                std::to_string(*index_pos) +
                                "); copy it again, or run `rosbag reindex` on a copy to keep the "
                                "messages before the cut");
      }
    } else if (opcode == 0x05) {  // a chunk
      const auto compression = fields.find("compression");
      facts.compressions.insert(compression == fields.end() ? "?" : compression->second);
    }
    if (!index_pos.has_value()) {
      return Status::DataLoss("bag " + Quoted(path) + " is damaged: it has no bag header");
    }
    at += 4 + header_size + 4 + uint64_t(data_size);
  }
  return facts;
}

class Ros1Store : public BagStore {
 public:
  static StatusOr<std::unique_ptr<BagStore>> Open(const std::string& path) {
    RECOG_ASSIGN_OR_RETURN(const Ros1FileFacts facts, CheckRos1File(path));
    auto store = std::unique_ptr<Ros1Store>(new Ros1Store(path));
    RECOG_RETURN_IF_ERROR(store->Guarded("its index", [&] {
      store->bag_.open(path, rosbag::bagmode::Read);
      return store->Summarize(facts);
    }));
    return std::unique_ptr<BagStore>(std::move(store));
  }

  const BagSummary& summary() const override { return summary_; }

  Status ForEachMessage(const std::string& topic,
                        const std::function<Status(const StoredMessage&)>& visit) override {
    RECOG_ASSIGN_OR_RETURN(const std::vector<rosbag::MessageInstance>* messages, Messages(topic));
    std::vector<uint8_t> bytes;
    for (size_t i = 0; i < messages->size(); ++i) {
      RECOG_RETURN_IF_ERROR(ReadInto((*messages)[i], topic, &bytes));
      RECOG_RETURN_IF_ERROR(visit({i, Nanoseconds((*messages)[i].getTime()), bytes}));
    }
    return Status::Ok();
  }

  Status ReadMessage(const std::string& topic, uint64_t id, std::vector<uint8_t>* data) override {
    RECOG_ASSIGN_OR_RETURN(const std::vector<rosbag::MessageInstance>* messages, Messages(topic));
    if (id >= messages->size()) {
      return Status::InvalidArgument("topic " + topic + " of bag " + Quoted(summary_.path) +
                                     " has no message " + std::to_string(id));
    }
    return ReadInto((*messages)[id], topic, data);
  }

 private:
  explicit Ros1Store(const std::string& path) { summary_.path = path; }

  // Runs `read` (librosbag and roscpp_serialization throw); their exceptions become DATA_LOSS
  // naming the bag and what was read.
  template <typename Read>
  Status Guarded(const std::string& what, Read&& read) {
    try {
      return read();
    } catch (const rosbag::BagUnindexedException&) {
      return Status::DataLoss("bag " + Quoted(summary_.path) +
                              " is unindexed: run `rosbag reindex " + summary_.path +
                              "` to rebuild its index");
    } catch (const std::exception& e) {
      return Status::DataLoss("bag " + Quoted(summary_.path) + " cannot be read (" + what +
                              "): " + e.what() + " (a damaged or truncated file?)");
    }
  }

  Status Summarize(const Ros1FileFacts& facts) {
    summary_.storage = "ros1";
    summary_.files = {summary_.path};
    for (const std::string& c : facts.compressions) {
      summary_.compression += (summary_.compression.empty() ? "" : ", ") + c;
    }
    if (summary_.compression.empty()) summary_.compression = "none";
    std::map<std::string, TopicSummary> topics;
    rosbag::View all(bag_);
    for (const rosbag::ConnectionInfo* c : all.getConnections()) {
      TopicSummary& t = topics[c->topic];
      if (!t.type.empty() && t.type != c->datatype) {
        return Status::InvalidArgument("topic " + c->topic + " of bag " + Quoted(summary_.path) +
                                       " has messages of two types: " + t.type + " and " +
                                       c->datatype);
      }
      const auto known = KnownDefinitions().find(c->datatype);
      if (known != KnownDefinitions().end() && known->second != c->md5sum) {
        return Status::InvalidArgument(
            "topic " + c->topic + " of bag " + Quoted(summary_.path) + ": its " + c->datatype +
            " messages have another definition (MD5 " + c->md5sum + ") than ROS 1's");
      }
      t.name = c->topic;
      t.type = c->datatype;
      t.serialization = Serialization::kRos1;
    }
    for (auto& [name, t] : topics) {
      t.messages = rosbag::View(bag_, rosbag::TopicQuery(name)).size();
      summary_.messages += t.messages;
      summary_.topics.push_back(std::move(t));
    }
    if (summary_.messages > 0) {
      summary_.start_ns = Nanoseconds(all.getBeginTime());
      summary_.end_ns = Nanoseconds(all.getEndTime());
    }
    return Status::Ok();
  }

  // The topic's messages in time order, listed at the first call.
  StatusOr<const std::vector<rosbag::MessageInstance>*> Messages(const std::string& topic) {
    if (const auto found = messages_.find(topic); found != messages_.end()) return &found->second;
    const bool listed = std::any_of(summary_.topics.begin(), summary_.topics.end(),
                                    [&](const TopicSummary& t) { return t.name == topic; });
    if (!listed) {
      return Status::NotFound("bag " + Quoted(summary_.path) + " has no topic " + topic);
    }
    std::vector<rosbag::MessageInstance> messages;
    RECOG_RETURN_IF_ERROR(Guarded("topic " + topic, [&] {
      rosbag::View view(bag_, rosbag::TopicQuery(topic));
      for (const rosbag::MessageInstance& m : view) messages.push_back(m);
      return Status::Ok();
    }));
    return &messages_.emplace(topic, std::move(messages)).first->second;
  }

  Status ReadInto(const rosbag::MessageInstance& m, const std::string& topic,
                  std::vector<uint8_t>* data) {
    return Guarded("topic " + topic, [&] {
      data->resize(m.size());
      ros::serialization::OStream stream(data->data(), uint32_t(data->size()));
      m.write(stream);
      return Status::Ok();
    });
  }

  BagSummary summary_;
  rosbag::Bag bag_;
  std::map<std::string, std::vector<rosbag::MessageInstance>> messages_;
};

}  // namespace

StatusOr<std::unique_ptr<BagStore>> OpenRos1Bag(const std::string& path) {
  return Ros1Store::Open(path);
}

}  // namespace recog::bag
