// transport::Router: pattern matching, path parameters, which row serves a method, and the
// difference between a path no route has (404) and a method its route does not serve (405).
#include "transport/router.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace rcan::transport {
namespace {

TEST(RouterPattern, LiteralsParametersAndTheRest) {
  std::vector<std::string> p;
  EXPECT_TRUE(match_path("/rcan/v1/leases", "/rcan/v1/leases", &p));
  EXPECT_TRUE(p.empty());
  EXPECT_FALSE(match_path("/rcan/v1/leases", "/rcan/v1/leases/", &p));
  EXPECT_FALSE(match_path("/rcan/v1/leases", "/rcan/v1/leasesX", &p));
  EXPECT_FALSE(match_path("/rcan/v1/leases", "/rcan/v1", &p));
  EXPECT_TRUE(match_path("/rcan/v1/leases/{id}/grants", "/rcan/v1/leases/L-1/grants", &p));
  EXPECT_EQ(p, std::vector<std::string>{"L-1"});
  EXPECT_FALSE(match_path("/rcan/v1/leases/{id}", "/rcan/v1/leases/", &p))
      << "a parameter is never empty";
  EXPECT_FALSE(match_path("/rcan/v1/leases/{id}", "/rcan/v1/leases/a/b", &p));
  EXPECT_TRUE(match_path("/x/{id}", "/x/" + std::string(128, 'a'), &p));
  EXPECT_FALSE(match_path("/x/{id}", "/x/" + std::string(129, 'a'), &p))
      << "a parameter is at most 128 bytes";
  EXPECT_TRUE(match_path("/ui/*", "/ui/js/main.js", &p));
  EXPECT_EQ(p, std::vector<std::string>{"js/main.js"});
  EXPECT_TRUE(match_path("/keys/*", "/keys//x", &p)) << "the rest is taken whole";
  EXPECT_EQ(p, std::vector<std::string>{"/x"});
  EXPECT_FALSE(match_path("/ui/*", "/ui/", &p));
  EXPECT_FALSE(match_path("/ui/*", "/ui", &p));
  EXPECT_TRUE(match_path("/", "/", &p));
  EXPECT_FALSE(match_path("/", "/x", &p));
  EXPECT_FALSE(match_path("/x", "", &p));
  EXPECT_FALSE(match_path("/x", "x", &p));
  EXPECT_FALSE(match_path("", "/", &p));
  EXPECT_TRUE(match_path("/a/{x}/b/{y}", "/a/1/b/2", &p));
  EXPECT_EQ(p, (std::vector<std::string>{"1", "2"}));
  EXPECT_TRUE(match_path("/a/{x}", "/a/1", nullptr)) << "parameters are optional to collect";
}

using Table = Router<int>;

Table table() {
  Table t;
  t.add("GET", "/robots", 1);
  t.add("POST", "/robots", 2);
  t.add("GET", "/robots/search", 3);
  t.add("GET", "/robots/*", 4, "/robots/{rrn}");
  t.add("DELETE", "/robots/*", 5, "/robots/{rrn}");
  t.add("*", "/oauth/token", 6);
  t.add("GET", "/leases/{id}/grants", 7);
  return t;
}

TEST(Router, FindsTheRowOfTheMethodWithItsParametersAndLabel) {
  const Table t = table();
  auto m = t.find("POST", "/robots");
  ASSERT_TRUE(m.found());
  EXPECT_EQ(m.route->handler, 2);
  EXPECT_EQ(m.route->label, "/robots") << "the label defaults to the pattern";
  EXPECT_TRUE(m.params.empty());
  m = t.find("DELETE", "/robots/RRN-1");
  ASSERT_TRUE(m.found());
  EXPECT_EQ(m.route->handler, 5);
  EXPECT_EQ(m.route->label, "/robots/{rrn}");
  EXPECT_EQ(m.route->pattern, "/robots/*");
  EXPECT_EQ(m.params, std::vector<std::string>{"RRN-1"});
  m = t.find("GET", "/leases/L-1/grants");
  ASSERT_TRUE(m.found());
  EXPECT_EQ(m.params, std::vector<std::string>{"L-1"});
}

TEST(Router, APathsRouteIsItsFirstMatchingPattern) {
  const Table t = table();
  auto m = t.find("GET", "/robots/search");
  ASSERT_TRUE(m.found());
  EXPECT_EQ(m.route->handler, 3);
  // /robots/* would serve DELETE, but the path's route is /robots/search: a 405, never the
  // later pattern's handler.
  m = t.find("DELETE", "/robots/search");
  EXPECT_FALSE(m.found());
  EXPECT_TRUE(m.method_not_allowed());
  EXPECT_EQ(m.allow, "GET");
  EXPECT_EQ(m.label_or("other"), "/robots/search");
}

TEST(Router, AnUnknownPathIsNotFoundAndAWrongMethodIsNotAllowed) {
  const Table t = table();
  for (const char* path : {"/nope", "/robots/", "/robotsX", "/leases/L-1", ""}) {
    auto m = t.find("GET", path);
    EXPECT_FALSE(m.found()) << path;
    EXPECT_FALSE(m.method_not_allowed()) << path;
    EXPECT_TRUE(m.params.empty()) << path;
    EXPECT_EQ(m.label_or("other"), "other") << path;
  }
  auto m = t.find("PUT", "/robots");
  EXPECT_TRUE(m.method_not_allowed());
  EXPECT_EQ(m.allow, "GET, POST") << "every method of the route, in the order added";
  EXPECT_EQ(m.path->pattern, "/robots");
  m = t.find("PATCH", "/robots/RRN-1");
  EXPECT_TRUE(m.method_not_allowed());
  EXPECT_EQ(m.allow, "GET, DELETE");
  EXPECT_EQ(m.label_or("other"), "/robots/{rrn}");
}

TEST(Router, AnyMethodRowsAndMethodListing) {
  const Table t = table();
  for (const char* method : {"GET", "POST", "BREW"}) {
    auto m = t.find(method, "/oauth/token");
    ASSERT_TRUE(m.found()) << method;
    EXPECT_EQ(m.route->handler, 6);
  }
  Table dup;
  dup.add("GET", "/x", 1);
  dup.add("HEAD", "/x", 2);
  dup.add("GET", "/x", 3);  // never reached: the first GET row serves
  auto m = dup.find("POST", "/x");
  EXPECT_EQ(m.allow, "GET, HEAD") << "each method listed once";
  m = dup.find("GET", "/x");
  ASSERT_TRUE(m.found());
  EXPECT_EQ(m.route->handler, 1);
  EXPECT_EQ(dup.routes().size(), 3u);
}

}  // namespace
}  // namespace rcan::transport
