// The registry store tests' fixture (store_test.cpp): each test runs against every backend,
// SQLite in a fresh temporary directory, PostgreSQL in a fresh database on a server the suite
// starts once.
#pragma once

#include <gtest/gtest.h>

#include <cstdio>
#include <memory>
#include <string>

#include "registry/store.h"
#include "test_support.h"

namespace rcan::registry::testing {

// "2026-11-27T05:20:00.000Z" plus `i` seconds (i < 86,400): later i, later time.
inline std::string at(int i) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "2026-11-27T%02d:%02d:%02d.000Z", i / 3600, (i / 60) % 60, i % 60);
  return buf;
}

inline NewRobot new_robot(const std::string& device_id, const std::string& now = at(0),
                          const std::string& manufacturer = "acme",
                          const std::string& model = "rover") {
  NewRobot r;
  r.manufacturer = manufacturer;
  r.model = model;
  r.version = "v1";
  r.device_id = device_id;
  r.rcan_uri_base = "rcan://registry.example";
  r.description = "a robot";
  r.owner_key_id = "0123456789abcdef";
  r.now = now;
  return r;
}

class StoreTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    auto s = open();
    ASSERT_TRUE(s.ok()) << s.error().message;
    store_ = std::move(*s);
    ASSERT_EQ(store_->backend(), GetParam());
  }
  static void TearDownTestSuite();

  bool postgres() const { return GetParam() == "postgresql"; }
  // Another Store on this test's database (a second process, or a restart).
  Result<std::unique_ptr<Store>> open(const StoreOptions& o = {});
  // What open_store takes for this test's database.
  std::string spec();
  // What open_store takes for another, empty database (`name`: a new one each call).
  std::string fresh_spec(const std::string& name);

  test::TempDir tmp_;
  std::unique_ptr<Store> store_;
  std::string pg_database_;
};

}  // namespace rcan::registry::testing
