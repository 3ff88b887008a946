"""Maps: the map server and saver (nav2_map_server's job) and the map file format."""
