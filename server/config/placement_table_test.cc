// PlacementTable: the nginx-map file format, and its refusals.
#include "server/config/placement_table.h"

#include <gtest/gtest.h>

namespace recog::server {
namespace {

TEST(PlacementTableTest, EntriesCommentsAndBlankLinesAreRead) {
  auto table = PlacementTable::Parse(
      "# map            shard\n"
      "hall-robot-1     shard_a;\n"
      "\n"
      "yard.robot_2\tshard_b ;   # trailing comment\n",
      "placement.map");
  ASSERT_TRUE(table.ok()) << table.status().ToString();
  EXPECT_EQ(table->size(), 2u);
  EXPECT_EQ(table->OwnerOf("hall-robot-1"), "shard_a");
  EXPECT_EQ(table->OwnerOf("yard.robot_2"), "shard_b");
  EXPECT_EQ(table->OwnerOf("unlisted"), std::nullopt);
}

TEST(PlacementTableTest, AGroupLinePlacesEveryMapOfTheGroup) {
  auto table = PlacementTable::Parse(
      "group:fleet      shard_a;\n"
      "robot-1          shard_a;\n"
      "fleet            shard_b;   # a map named like the group is another entry\n",
      "placement.map");
  ASSERT_TRUE(table.ok()) << table.status().ToString();
  EXPECT_EQ(table->size(), 2u);
  EXPECT_EQ(table->groups(), 1u);
  EXPECT_EQ(table->OwnerOfGroup("fleet"), "shard_a");
  EXPECT_EQ(table->OwnerOf("fleet"), "shard_b");
  EXPECT_EQ(table->OwnerOf("group:fleet"), std::nullopt);
  EXPECT_EQ(table->OwnerOfGroup("robot-1"), std::nullopt);
}

TEST(PlacementTableTest, BadEntriesAreRefusedWithTheirLine) {
  const std::pair<const char*, const char*> cases[] = {
      {"hall shard_a\n", "placement.map:1: expected"},         // no semicolon
      {"hall\n", "placement.map:1: expected"},                 // no shard
      {"hall shard_a extra;\n", "placement.map:1: expected"},  // three words
      {"ok a;\ndefault shard_a;\n", "placement.map:2: 'default' is an nginx map keyword"},
      {"bad/name shard_a;\n", "placement.map:1: map name 'bad/name'"},
      {"hall shard-a;\n", "placement.map:1: shard name 'shard-a'"},
      {"hall a;\nhall b;\n", "placement.map:2: map 'hall' is listed twice"},
      {"group: shard_a;\n", "placement.map:1: group name must have"},
      {"group:a/b shard_a;\n", "placement.map:1: group name 'a/b'"},
      {"group:fleet a;\ngroup:fleet b;\n", "placement.map:2: group 'fleet' is listed twice"},
  };
  for (const auto& [text, expected] : cases) {
    auto table = PlacementTable::Parse(text, "placement.map");
    ASSERT_FALSE(table.ok()) << text;
    EXPECT_EQ(table.status().code(), StatusCode::kInvalidArgument) << text;
    EXPECT_NE(table.status().message().find(expected), std::string::npos)
        << table.status().message();
  }
  EXPECT_EQ(PlacementTable::Load("/nonexistent/placement.map").status().code(),
            StatusCode::kNotFound);
}

}  // namespace
}  // namespace recog::server
