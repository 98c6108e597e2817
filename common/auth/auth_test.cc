#include <sys/stat.h>

#include <fstream>

#include <gtest/gtest.h>

#include "common/auth/authenticator.h"
#include "common/auth/identity.h"
#include "common/auth/tokens.h"
#include "common/core/file_io.h"
#include "common/core/testing/temp_dir.h"

namespace instascene::auth {
namespace {

TEST(Tokens, CreatedTokensAreStoredHashedAndPrivate) {
  testing::ScopedTempDir dir("tokens");
  const std::string path = dir.Sub("auth/tokens.json");
  TokenRecord record;
  absl::StatusOr<std::string> token = CreateToken(path, Role::kClient, "acme", "robot 7", &record);
  ASSERT_TRUE(token.ok()) << token.status();
  std::string id, secret;
  ASSERT_TRUE(SplitToken(*token, &id, &secret).ok());
  EXPECT_EQ(id, record.id);
  const std::string file = *ReadFileBounded(path, 1 << 20);
  EXPECT_EQ(file.find(secret), std::string::npos) << "the secret must never be stored";
  EXPECT_NE(file.find(HashSecret(secret)), std::string::npos);
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600);
  absl::StatusOr<TokenFile> loaded = LoadTokenFile(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ASSERT_EQ(loaded->tokens.size(), 1u);
  EXPECT_EQ(loaded->tokens[0].tenant, "acme");
  EXPECT_EQ(loaded->tokens[0].role, Role::kClient);
  EXPECT_EQ(loaded->tokens[0].note, "robot 7");
}

TEST(Tokens, BadRequestsAndFilesAreRefused) {
  testing::ScopedTempDir dir("tokens_bad");
  const std::string path = dir.Sub("tokens.json");
  EXPECT_FALSE(CreateToken(path, Role::kClient, "", "").ok()) << "client tokens need a tenant";
  EXPECT_FALSE(CreateToken(path, Role::kClient, "Acme", "").ok()) << "upper case";
  EXPECT_FALSE(CreateToken(path, Role::kClient, "a:b", "").ok())
      << "':' separates tenant and scene";
  EXPECT_FALSE(CreateToken(path, Role::kClient, std::string(33, 'a'), "").ok());
  EXPECT_FALSE(CreateToken(path, Role::kAdmin, "acme", "").ok()) << "admins span every tenant";
  EXPECT_FALSE(ParseRole("root").ok());
  EXPECT_TRUE(absl::IsNotFound(RevokeToken(path, "000000000000")));
  for (
      const char* json :
      {"[]", R"({"format":2,"tokens":[]})", R"({"format":1})",
       R"({"format":1,"tokens":[{"id":"x","tenant":"","role":"admin","secret_sha256":"","note":""}]})",
       R"({"format":1,"tokens":[{"id":"0123456789ab","tenant":"","role":"client","secret_sha256":"0000000000000000000000000000000000000000000000000000000000000000","note":""}]})"}) {
    EXPECT_TRUE(absl::IsInvalidArgument(TokenFile::Parse(json, "t").status())) << json;
  }
  std::string id, secret;
  for (const char* bad : {"", "isk_", "isk_0123456789ab_zz", "Bearer isk_x", "isk_0123456789AB_"})
    EXPECT_FALSE(SplitToken(bad, &id, &secret).ok()) << bad;
}

TEST(Authenticator, AcceptsValidTokensAndFollowsRevocations) {
  testing::ScopedTempDir dir("authn");
  const std::string path = dir.Sub("tokens.json");
  TokenRecord admin_record;
  const std::string admin = *CreateToken(path, Role::kAdmin, "", "", &admin_record);
  const std::string client = *CreateToken(path, Role::kClient, "acme", "");
  absl::StatusOr<std::shared_ptr<Authenticator>> auth =
      Authenticator::FromFile(path, std::chrono::milliseconds(0));
  ASSERT_TRUE(auth.ok()) << auth.status();
  absl::StatusOr<Identity> who = (*auth)->Authenticate("Bearer " + client);
  ASSERT_TRUE(who.ok()) << who.status();
  EXPECT_EQ(who->tenant, "acme");
  EXPECT_EQ(who->role, Role::kClient);
  EXPECT_TRUE((*auth)->Authenticate("Bearer " + admin).ok());
  // A wrong secret, a missing scheme, garbage: all the same UNAUTHENTICATED.
  std::string wrong = admin;
  wrong.back() = wrong.back() == '0' ? '1' : '0';
  for (const std::string& bad :
       {"Bearer " + wrong, admin, std::string("Bearer nope"), std::string()})
    EXPECT_TRUE(absl::IsUnauthenticated((*auth)->Authenticate(bad).status())) << bad;
  // Revocation is seen at the next call (the file changed); a new token too.
  ASSERT_TRUE(RevokeToken(path, admin_record.id).ok());
  const std::string later = *CreateToken(path, Role::kWorker, "", "");
  EXPECT_TRUE(absl::IsUnauthenticated((*auth)->Authenticate("Bearer " + admin).status()));
  EXPECT_TRUE((*auth)->Authenticate("Bearer " + later).ok());
  // A process token is valid here only; a corrupt file keeps the last good tokens.
  absl::StatusOr<std::string> process = (*auth)->AddProcessToken(Role::kWorker);
  ASSERT_TRUE(process.ok());
  EXPECT_EQ(LoadTokenFile(path)->tokens.size(), 3u);
  EXPECT_EQ((*auth)->Authenticate("Bearer " + *process)->role, Role::kWorker);
  ASSERT_TRUE(WriteFileAtomically(path, "{ not json").ok());
  EXPECT_TRUE((*auth)->Authenticate("Bearer " + client).ok());
  EXPECT_TRUE(Authenticator::Disabled()->Authenticate("").ok());
}

TEST(Identity, TenantsSeeOnlyTheirScenesUnderTheirOwnNames) {
  Identity acme{"id", "acme", Role::kClient};
  const Identity admin = Identity::Unrestricted();
  EXPECT_EQ(StoredScene(acme, "kitchen"), "acme:kitchen");
  EXPECT_EQ(StoredScene(acme, "a:b"), "acme:a:b");
  EXPECT_EQ(StoredScene(acme, ""), "");
  EXPECT_EQ(StoredScene(admin, "kitchen"), "kitchen");
  EXPECT_TRUE(MaySee(acme, "acme:kitchen"));
  EXPECT_FALSE(MaySee(acme, "acmex:kitchen"));
  EXPECT_FALSE(MaySee(acme, "kitchen"));
  EXPECT_TRUE(MaySee(admin, "beta:kitchen"));
  EXPECT_EQ(ShownScene(acme, "acme:a:b"), "a:b");
  EXPECT_EQ(ShownScene(admin, "acme:a:b"), "acme:a:b");
  EXPECT_EQ(SceneTenant("acme:a:b"), "acme");
  EXPECT_EQ(SceneTenant("kitchen"), "");
  EXPECT_EQ(SceneTenant("Not A Tenant:x"), "");
}

}  // namespace
}  // namespace instascene::auth
