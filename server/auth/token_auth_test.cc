#include "server/auth/token_auth.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "wire/sha256.h"

namespace recog::server {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;

constexpr char kReaderToken[] = "reader-token-0123456789";
constexpr char kWriterToken[] = "writer-token-0123456789";
constexpr char kBothToken[] = "both-rights-0123456789";

constexpr char kTokenFile[] = R"(tokens:
  - name: robot-7
    token: "reader-token-0123456789"
    rights: [read]
  - name: mapper
    token: writer-token-0123456789
    rights: [write]
  - name: operator
    token: "both-rights-0123456789"
    rights: [read, write]
)";

class TokenAuthTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("recog_token_auth_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  StatusOr<TokenAuthenticator> LoadText(const std::string& yaml) {
    const fs::path path = dir_ / "tokens.yaml";
    std::ofstream(path) << yaml;
    return TokenAuthenticator::Load(path.string());
  }

  fs::path dir_;
};

TEST_F(TokenAuthTest, EachTokenAuthenticatesAsItsNameWithItsRights) {
  StatusOr<TokenAuthenticator> auth = LoadText(kTokenFile);
  ASSERT_TRUE(auth.ok()) << auth.status().ToString();
  EXPECT_FALSE(auth->allows_all());

  StatusOr<Caller> reader = auth->Authenticate(std::string("Bearer ") + kReaderToken);
  ASSERT_TRUE(reader.ok()) << reader.status().ToString();
  EXPECT_EQ(reader->name, "robot-7");
  EXPECT_TRUE(reader->can_read);
  EXPECT_FALSE(reader->can_write);

  StatusOr<Caller> writer = auth->Authenticate(std::string("Bearer ") + kWriterToken);
  ASSERT_TRUE(writer.ok());
  EXPECT_EQ(writer->name, "mapper");
  EXPECT_TRUE(writer->can_read);  // write implies read
  EXPECT_TRUE(writer->can_write);

  StatusOr<Caller> both = auth->Authenticate(std::string("Bearer ") + kBothToken);
  ASSERT_TRUE(both.ok());
  EXPECT_EQ(both->name, "operator");
  EXPECT_TRUE(both->can_read);
  EXPECT_TRUE(both->can_write);
}

TEST_F(TokenAuthTest, TheSchemeIsCaseInsensitiveAndSurroundingSpacesAreIgnored) {
  StatusOr<TokenAuthenticator> auth = LoadText(kTokenFile);
  ASSERT_TRUE(auth.ok());
  for (const std::string& header :
       {std::string("bearer ") + kReaderToken, std::string("BEARER ") + kReaderToken,
        std::string("  Bearer \t ") + kReaderToken + "  "}) {
    StatusOr<Caller> caller = auth->Authenticate(header);
    ASSERT_TRUE(caller.ok()) << header;
    EXPECT_EQ(caller->name, "robot-7");
  }
}

TEST_F(TokenAuthTest, MissingMalformedAndUnknownTokensAreUnauthenticated) {
  StatusOr<TokenAuthenticator> auth = LoadText(kTokenFile);
  ASSERT_TRUE(auth.ok());
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"", "missing authorization header"},
      {"   ", "missing authorization header"},
      {kReaderToken, "malformed"},
      {std::string("Basic ") + kReaderToken, "malformed"},
      {"Bearer", "malformed"},
      {"Bearer ", "malformed"},
      {std::string("Bearer ") + kReaderToken + " extra", "malformed"},
      {"Bearer not-a-known-token-at-all", "unknown token"},
      {std::string("Bearer ") + kReaderToken + "x", "unknown token"},
      {std::string("Bearer ") + std::string(kReaderToken).substr(1), "unknown token"},
  };
  for (const auto& [header, expected] : cases) {
    StatusOr<Caller> caller = auth->Authenticate(header);
    ASSERT_FALSE(caller.ok()) << header;
    EXPECT_EQ(caller.status().code(), StatusCode::kUnauthenticated) << header;
    EXPECT_THAT(caller.status().message(), HasSubstr(expected)) << header;
    EXPECT_THAT(caller.status().message(), Not(HasSubstr("token-0123"))) << header;
  }
}

TEST_F(TokenAuthTest, CheckDeniesRightsTheCallerDoesNotHold) {
  const Caller reader{.name = "robot-7", .can_read = true};
  EXPECT_TRUE(TokenAuthenticator::Check(reader, Right::kRead).ok());
  const Status denied = TokenAuthenticator::Check(reader, Right::kWrite);
  EXPECT_EQ(denied.code(), StatusCode::kPermissionDenied);
  EXPECT_THAT(denied.message(), HasSubstr("'robot-7'"));
  EXPECT_THAT(denied.message(), HasSubstr("write"));

  const Caller nobody{.name = "nobody"};
  EXPECT_EQ(TokenAuthenticator::Check(nobody, Right::kRead).code(), StatusCode::kPermissionDenied);
  const Caller writer{.name = "mapper", .can_read = true, .can_write = true};
  EXPECT_TRUE(TokenAuthenticator::Check(writer, Right::kWrite).ok());
}

TEST_F(TokenAuthTest, AScopedTokenReachesOnlyTheMapsItsPatternsCover) {
  StatusOr<TokenAuthenticator> auth = LoadText(R"(tokens:
  - name: robot-7
    token: robot-7-token-0123456789
    rights: [write]
    maps:
      write: ["robot-7*", scratch]
      read: ["group:fleet"]
  - name: viewer
    token: viewer-token-0123456789
    rights: [read]
    maps: {read: [robot-3]}
  - name: operator
    token: operator-token-0123456789
    rights: [write]
)");
  ASSERT_TRUE(auth.ok()) << auth.status().ToString();
  const Caller robot = auth->Authenticate("Bearer robot-7-token-0123456789").value();
  const auto allowed = [](const Caller& caller, Right right, const char* map, const char* group) {
    return TokenAuthenticator::CheckMap(caller, right, map, group).ok();
  };
  EXPECT_TRUE(allowed(robot, Right::kWrite, "robot-7", ""));
  EXPECT_TRUE(allowed(robot, Right::kWrite, "robot-7-tuesday", "fleet"));  // the prefix
  EXPECT_TRUE(allowed(robot, Right::kWrite, "scratch", ""));
  EXPECT_FALSE(allowed(robot, Right::kWrite, "scratch-2", ""));   // a name is not a prefix
  EXPECT_TRUE(allowed(robot, Right::kRead, "robot-7", ""));       // write implies read
  EXPECT_TRUE(allowed(robot, Right::kRead, "robot-3", "fleet"));  // its group's
  EXPECT_FALSE(allowed(robot, Right::kWrite, "robot-3", "fleet"));
  EXPECT_FALSE(allowed(robot, Right::kRead, "robot-3", ""));  // not in the group
  EXPECT_FALSE(allowed(robot, Right::kRead, "robot-3", "other-fleet"));
  const Status denied = TokenAuthenticator::CheckMap(robot, Right::kWrite, "robot-3", "fleet");
  EXPECT_EQ(denied.code(), StatusCode::kPermissionDenied);
  EXPECT_THAT(denied.message(), HasSubstr("'robot-7' may not write map 'robot-3'"));

  const Caller viewer = auth->Authenticate("Bearer viewer-token-0123456789").value();
  EXPECT_TRUE(allowed(viewer, Right::kRead, "robot-3", "fleet"));
  EXPECT_FALSE(allowed(viewer, Right::kRead, "robot-7", "fleet"));
  const Status no_write = TokenAuthenticator::CheckMap(viewer, Right::kWrite, "robot-3", "");
  EXPECT_EQ(no_write.code(), StatusCode::kPermissionDenied);
  EXPECT_THAT(no_write.message(), HasSubstr("does not have the write right"));

  const Caller op = auth->Authenticate("Bearer operator-token-0123456789").value();
  EXPECT_TRUE(allowed(op, Right::kWrite, "robot-3", "fleet"));  // no maps: every map
  EXPECT_TRUE(allowed(op, Right::kRead, "anything", ""));
}

TEST_F(TokenAuthTest, AllowAllLetsEveryCallerDoEverythingAsAnonymous) {
  const TokenAuthenticator auth = TokenAuthenticator::AllowAll();
  EXPECT_TRUE(auth.allows_all());
  for (const std::string& header :
       {std::string(), std::string("Bearer whatever"), std::string("garbage")}) {
    StatusOr<Caller> caller = auth.Authenticate(header);
    ASSERT_TRUE(caller.ok()) << header;
    EXPECT_EQ(caller->name, "anonymous");
    EXPECT_TRUE(TokenAuthenticator::Check(*caller, Right::kRead).ok());
    EXPECT_TRUE(TokenAuthenticator::Check(*caller, Right::kWrite).ok());
  }
}

TEST_F(TokenAuthTest, MissingFileIsNotFound) {
  StatusOr<TokenAuthenticator> auth = TokenAuthenticator::Load((dir_ / "absent.yaml").string());
  ASSERT_FALSE(auth.ok());
  EXPECT_EQ(auth.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(auth.status().message(), HasSubstr("absent.yaml"));
}

TEST_F(TokenAuthTest, BadEntriesAreRejectedNamingTheEntryButNeverTheSecret) {
  const std::string good = "  - name: good\n    token: good-token-0123456789\n    rights: [read]\n";
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      {"  - name: short\n    token: short-secret\n    rights: [read]\n",
       {"entry 2 (line 5)", "'short'", "at least 16 characters"}},
      {"  - name: dup\n    token: good-token-0123456789\n    rights: [write]\n",
       {"entry 2 (line 5) ('dup') has the same token as entry 1 (line 2) ('good')"}},
      {"  - name: bad-right\n    token: other-token-0123456789\n    rights: [read, admin]\n",
       {"entry 2", "unknown right 'admin'"}},
      {"  - name: \"\"\n    token: other-token-0123456789\n    rights: [read]\n",
       {"entry 2", "non-empty name"}},
      {"  - token: other-token-0123456789\n    rights: [read]\n", {"entry 2", "non-empty name"}},
      {"  - name: no-token\n    rights: [read]\n", {"entry 2", "('no-token') needs a token"}},
      {"  - name: no-rights\n    token: other-token-0123456789\n", {"entry 2", "list of rights"}},
      {"  - name: empty-rights\n    token: other-token-0123456789\n    rights: []\n",
       {"entry 2", "list of rights"}},
      {"  - name: typo\n    token: other-token-0123456789\n    right: [read]\n",
       {"entry 2", "unknown key 'right'"}},
      {"  - name: spaces\n    token: \"other token 0123456789\"\n    rights: [read]\n",
       {"entry 2", "visible ASCII"}},
      {"  - just-a-string\n", {"entry 2", "must be a mapping"}},
      {"  - name: scoped\n    token: other-token-0123456789\n    rights: [write]\n"
       "    maps: robot-7\n",
       {"entry 2", "maps must be a mapping"}},
      {"  - name: scoped\n    token: other-token-0123456789\n    rights: [write]\n"
       "    maps: {delete: [robot-7]}\n",
       {"entry 2", "unknown key 'delete'"}},
      {"  - name: scoped\n    token: other-token-0123456789\n    rights: [write]\n"
       "    maps: {write: robot-7}\n",
       {"entry 2", "maps.write must be a list"}},
      {"  - name: scoped\n    token: other-token-0123456789\n    rights: [write]\n"
       "    maps: {write: [\"robot-*-a\"]}\n",
       {"entry 2", "bad pattern 'robot-*-a'"}},
      {"  - name: scoped\n    token: other-token-0123456789\n    rights: [write]\n"
       "    maps: {read: [\"group:\"]}\n",
       {"entry 2", "maps.read", "bad pattern 'group:'"}},
      {"  - name: scoped\n    token: other-token-0123456789\n    rights: [read]\n"
       "    maps: {write: [robot-7]}\n",
       {"entry 2", "maps.write needs the write right"}},
  };
  for (const auto& [entry, expected] : cases) {
    StatusOr<TokenAuthenticator> auth = LoadText("tokens:\n" + good + entry);
    ASSERT_FALSE(auth.ok()) << entry;
    EXPECT_EQ(auth.status().code(), StatusCode::kInvalidArgument) << entry;
    for (const std::string& part : expected) {
      EXPECT_THAT(auth.status().message(), HasSubstr(part)) << entry;
    }
    EXPECT_THAT(auth.status().message(), Not(HasSubstr("0123456789"))) << entry;
    EXPECT_THAT(auth.status().message(), Not(HasSubstr("short-secret"))) << entry;
  }
}

TEST_F(TokenAuthTest, FilesWithoutATokenListAreRejected) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"", "must be a mapping"},
      {"tokens: []\n", "has no tokens"},
      {"{}\n", "has no tokens"},
      {"tokens:\n", "has no tokens"},
      {"tokens: robot\n", "has no tokens"},
      {"tokenz: []\n", "unknown key 'tokenz'"},
      {"tokens: [\n", "not valid YAML"},
  };
  for (const auto& [yaml, expected] : cases) {
    StatusOr<TokenAuthenticator> auth = LoadText(yaml);
    ASSERT_FALSE(auth.ok()) << yaml;
    EXPECT_EQ(auth.status().code(), StatusCode::kInvalidArgument) << yaml;
    EXPECT_THAT(auth.status().message(), HasSubstr(expected)) << yaml;
  }
}

// Names tell tokens apart in the logs, and a second token of the same name used to replay the
// first's answers from the request log: a rotated token takes a name of its own.
TEST_F(TokenAuthTest, TwoEntriesOfOneNameAreRefusedAndEachTokenHasItsOwnIdentity) {
  StatusOr<TokenAuthenticator> same = LoadText(R"(tokens:
  - name: robot-7
    token: old-token-0123456789
    rights: [write]
  - name: robot-7
    token: new-token-0123456789
    rights: [read]
)");
  ASSERT_FALSE(same.ok());
  EXPECT_EQ(same.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(same.status().message(), HasSubstr("('robot-7') has the same name as entry 1"));
  EXPECT_THAT(same.status().message(), Not(HasSubstr("0123456789")));

  StatusOr<TokenAuthenticator> rotated = LoadText(R"(tokens:
  - name: robot-7
    token: old-token-0123456789
    rights: [write]
  - name: robot-7-next
    token: new-token-0123456789
    rights: [write]
)");
  ASSERT_TRUE(rotated.ok()) << rotated.status().ToString();
  const Caller old_token = rotated->Authenticate("Bearer old-token-0123456789").value();
  const Caller new_token = rotated->Authenticate("Bearer new-token-0123456789").value();
  EXPECT_EQ(old_token.identity, Sha256Hex("old-token-0123456789"));
  EXPECT_EQ(new_token.identity, Sha256Hex("new-token-0123456789"));
  EXPECT_EQ(TokenAuthenticator::AllowAll().Authenticate("")->identity, "anonymous");
}

TEST_F(TokenAuthTest, ANameMustBePrintableAsciiForTheLogs) {
  for (const std::string& name : {std::string("\"robot\\n7\""), std::string("\"robot\\t7\""),
                                  std::string("\"caf\\xE9\""), std::string(65, 'a')}) {
    StatusOr<TokenAuthenticator> auth = LoadText(
        "tokens:\n  - name: " + name + "\n    token: some-token-0123456789\n    rights: [read]\n");
    ASSERT_FALSE(auth.ok()) << name;
    EXPECT_THAT(auth.status().message(), HasSubstr("printable ASCII")) << name;
  }
}

TEST_F(TokenAuthTest, AdminCallsNeedATokenThatReachesEveryMap) {
  StatusOr<TokenAuthenticator> auth = LoadText(R"(tokens:
  - name: operator
    token: operator-token-0123456789
    rights: [write]
  - name: robot-a
    token: robot-a-token-0123456789
    rights: [write]
    maps:
      write: ["robot-a*"]
  - name: viewer
    token: viewer-token-0123456789
    rights: [read]
    maps:
      read: ["group:fleet"]
  - name: reader
    token: reader-token-0123456789
    rights: [read]
)");
  ASSERT_TRUE(auth.ok()) << auth.status().ToString();
  const auto caller = [&](const std::string& token) {
    return auth->Authenticate("Bearer " + token + "-token-0123456789").value();
  };
  EXPECT_TRUE(TokenAuthenticator::CheckEveryMap(caller("operator"), Right::kWrite, "Verify").ok());
  EXPECT_TRUE(TokenAuthenticator::CheckEveryMap(caller("reader"), Right::kRead, "Status").ok());
  const Status scoped =
      TokenAuthenticator::CheckEveryMap(caller("robot-a"), Right::kWrite, "Checkpoint");
  EXPECT_EQ(scoped.code(), StatusCode::kPermissionDenied);
  EXPECT_THAT(scoped.message(), HasSubstr("'robot-a'"));
  EXPECT_THAT(scoped.message(), HasSubstr("Checkpoint"));
  EXPECT_EQ(TokenAuthenticator::CheckEveryMap(caller("viewer"), Right::kRead, "Status").code(),
            StatusCode::kPermissionDenied);
  EXPECT_EQ(TokenAuthenticator::CheckEveryMap(caller("reader"), Right::kWrite, "Verify").code(),
            StatusCode::kPermissionDenied);
}

TEST_F(TokenAuthTest, ReloadSwapsTheTokensForEveryCopyAndKeepsThemWhenTheFileIsBad) {
  StatusOr<TokenAuthenticator> loaded = LoadText(kTokenFile);
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  TokenAuthenticator reloader = *loaded;
  const TokenAuthenticator serving = *loaded;  // a copy, as the RPC handlers hold it
  ASSERT_TRUE(serving.Authenticate(std::string("Bearer ") + kReaderToken).ok());

  // The reader's token is rotated out, a new one comes in.
  std::ofstream(dir_ / "tokens.yaml") << R"(tokens:
  - name: robot-7
    token: rotated-token-0123456789
    rights: [read]
)";
  ASSERT_TRUE(reloader.Reload().ok());
  EXPECT_EQ(serving.Authenticate("Bearer rotated-token-0123456789")->name, "robot-7");
  StatusOr<Caller> removed = serving.Authenticate(std::string("Bearer ") + kReaderToken);
  ASSERT_FALSE(removed.ok());
  EXPECT_EQ(removed.status().code(), StatusCode::kUnauthenticated);

  // A malformed file, then a missing one: errors as Load's, and the rotated token still works.
  std::ofstream(dir_ / "tokens.yaml") << "tokens: [ {name: x, token: short, rights: [read]} ]\n";
  const Status bad = reloader.Reload();
  EXPECT_EQ(bad.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bad.message(), HasSubstr("at least 16"));
  fs::remove(dir_ / "tokens.yaml");
  EXPECT_EQ(reloader.Reload().code(), StatusCode::kNotFound);
  EXPECT_TRUE(serving.Authenticate("Bearer rotated-token-0123456789").ok());
  EXPECT_FALSE(serving.Authenticate(std::string("Bearer ") + kWriterToken).ok());
}

TEST_F(TokenAuthTest, ReloadOfAllowAllDoesNothing) {
  TokenAuthenticator auth = TokenAuthenticator::AllowAll();
  EXPECT_TRUE(auth.Reload().ok());
  EXPECT_TRUE(auth.allows_all());
  EXPECT_EQ(auth.Authenticate("")->name, "anonymous");
}

}  // namespace
}  // namespace recog::server
