#include "kin_test_util.hpp"
TEST_GROUP(Placeholder){};
